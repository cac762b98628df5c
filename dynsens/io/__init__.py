"""Result files (HDF5)."""
