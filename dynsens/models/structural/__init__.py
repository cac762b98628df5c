"""Structural models (building block 1 for structures), laid out as :mod:`dynsens.models.multibody`:
the model (:mod:`.model`), its builder (:mod:`.build`), its matrices (:mod:`.matrices`), its
compiled step (:mod:`.step`) and its element kinds (:mod:`.elements`)."""
