"""The case-file reference and its JSON Schema, generated from the key table (dynsens/case_keys/).

``python -m dynsens.case.schema --write`` writes docs/case-reference.md and docs/case.schema.json;
``--check`` exits 1 when they differ from what the table generates (a test runs it).  The schema
lets editors complete and check case files (draft 2020-12; the YAML language server reads it from
a first line ``# yaml-language-server: $schema=../docs/case.schema.json``).  It checks keys and
the kinds of their values; the loader's checks (units, ranges, names that must exist) go further.
"""
from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path
from typing import Any

from ..case_keys import NO_DEFAULT, SECTIONS, Key, Section

ROOT = Path(__file__).resolve().parents[2]
SCHEMA_PATH = ROOT / "docs" / "case.schema.json"
REFERENCE_PATH = ROOT / "docs" / "case-reference.md"

_EXPR: dict[str, Any] = {"anyOf": [{"type": "number"}, {"type": "string"}]}
# YAML 1.1 reads 5.0e5 (no exponent sign) as text; the loader takes it as the number it spells
_NUMBER: dict[str, Any] = {"anyOf": [{"type": "number"},
                     {"type": "string", "pattern": "^[+-]?([0-9]+[.]?[0-9]*|[.][0-9]+)([eE][+-]?[0-9]+)?$"}]}
_SCALAR: dict[str, dict[str, Any]] = {"number": _NUMBER, "expr": _EXPR, "string": {"type": "string"},
           "name": {"type": "string"}, "bool": {"type": "boolean"}, "integer": {"type": "integer"}, "any": {}}


def _ref(name: str) -> dict[str, Any]:
    return {"$ref": f"#/$defs/{name}"}


def _items(item: str | tuple[str, ...] | None) -> dict[str, Any]:
    if item is None:
        return {}
    if isinstance(item, tuple):
        return {"anyOf": [_ref(i) for i in item]}
    if item in SECTIONS:
        return _ref(item)
    return dict(_SCALAR[item])


def _key_schema(key: Key) -> dict[str, Any]:
    kind = key.kind
    if kind == "enum":
        out: dict[str, Any] = {"enum": list(key.values)}
    elif kind == "vector":
        out = {"type": "array", "items": _EXPR}
        if key.length:
            out.update(minItems=key.length, maxItems=key.length)
    elif kind == "list":
        out = {"type": "array", "items": _items(key.item)}
    elif kind == "map":
        out = {"type": "object", "additionalProperties": _items(key.item)}
    elif kind == "section":
        out = _items(key.item)
    else:
        out = dict(_SCALAR[kind])
    out["description"] = key.doc
    if key.default is not NO_DEFAULT and isinstance(key.default, (int, float, bool, str, list)) \
            and not (isinstance(key.default, str) and kind in ("number", "expr", "integer", "bool")):
        out["default"] = key.default
    return out


def _section_schema(sec: Section) -> dict[str, Any]:
    props = {k.name: _key_schema(k) for k in sec.keys}
    out: dict[str, Any] = {"type": "object", "title": sec.title, "description": sec.doc, "properties": props,
                           "additionalProperties": False}
    req = [k.name for k in sec.keys if k.required]
    if req:
        out["required"] = req
    if sec.type_value is not None:
        props["type"] = {**props["type"], "const": sec.type_value}
        props["type"].pop("enum", None)
    return out


def json_schema() -> dict[str, Any]:
    """The JSON Schema of a case file (draft 2020-12)."""
    defs = {name: _section_schema(sec) for name, sec in SECTIONS.items() if name != "case"}
    # markers: a vector or the mapping form; the section of a marker map accepts both
    defs["multibody.body"]["properties"]["markers"]["additionalProperties"] = {
        "anyOf": [{"type": "array", "items": _EXPR, "minItems": 3, "maxItems": 3}, _ref("multibody.marker")]}
    # model bodies: 'ground' only has markers (the loader checks the rest)
    top = _section_schema(SECTIONS["case"])
    return {"$schema": "https://json-schema.org/draft/2020-12/schema",
            "$id": "https://dynsens.invalid/case.schema.json",
            "title": "dynsens case file",
            "description": "Generated from dynsens/case_keys/ by `python -m dynsens.case.schema --write`; "
                           "do not edit by hand.",
            **{k: v for k, v in top.items() if k not in ("title", "description")},
            "$defs": defs}


def _fmt_default(key: Key) -> str:
    if key.required:
        return "**required**"
    if key.default is NO_DEFAULT:
        return ""
    d = key.default
    return f"`{json.dumps(d) if not isinstance(d, str) else d}`"


def _fmt_kind(key: Key) -> str:
    if key.kind == "enum":
        return " \\| ".join(f"`{v}`" for v in key.values)
    if key.kind in ("list", "map", "section") and key.item is not None:
        items = key.item if isinstance(key.item, tuple) else (key.item,)
        names = ", ".join(f"[{SECTIONS[i].title}](#{_anchor(i)})" if i in SECTIONS else i for i in items)
        return {"list": f"list of {names}", "map": f"mapping name → {names}", "section": names}[key.kind]
    if key.kind == "vector":
        return f"vector of {key.length} numbers/expressions" if key.length else "list of numbers/expressions"
    return {"expr": "number or expression"}.get(key.kind, key.kind)


def _anchor(name: str) -> str:
    return "k-" + name.replace(".", "-").replace("_", "-")


def reference_markdown() -> str:
    """docs/case-reference.md: every section and key of the case language."""
    lines = ["# Case-file reference (every accepted key)", "",
             "Generated from `dynsens/case_keys/`, the table the case loader checks keys against, by "
             "`python -m dynsens.case.schema --write`; do not edit by hand. A tour by example is "
             "[case-files.md](case-files.md); the JSON Schema for editors is [case.schema.json](case.schema.json).", "",
             "Kinds: *number or expression* is a number or an expression of the design variables "
             "(`+ - * / **`, `sin cos tan asin acos atan atan2 sinh cosh tanh sqrt exp log log10 abs min max "
             "deg rad`, `pi e`). Quantities (the `quantity` of events and responses) are model-specific: "
             "[structural](#k-structural-quantity), [multibody](#k-multibody-quantity).", "",
             "Sections:", ""]
    lines += [f"- [{sec.title}](#{_anchor(name)})" for name, sec in SECTIONS.items()]
    for name, sec in SECTIONS.items():
        lines += ["", f'<a id="{_anchor(name)}"></a>', "", f"## {sec.title}", "", sec.doc, "",
                  "| key | takes | default | meaning |", "|---|---|---|---|"]
        for k in sec.keys:
            doc = k.doc.replace("|", "\\|")
            lines.append(f"| `{k.name}` | {_fmt_kind(k)} | {_fmt_default(k)} | {doc} |")
    return "\n".join(lines) + "\n"


def generated() -> dict[Path, str]:
    """The generated files and their contents (with the key sections the element kinds, the force
    laws and the response types declare)."""
    from ..models.multibody.force_law import load_laws
    from ..models.structural.elements import load_kinds
    from ..responses.types import load_response_types
    load_kinds()
    load_laws()
    load_response_types()
    return {SCHEMA_PATH: json.dumps(json_schema(), indent=1, ensure_ascii=False) + "\n",
            REFERENCE_PATH: reference_markdown()}


def main(argv: list[str] | None = None) -> int:
    """Command-line entry point: --write or --check."""
    ap = argparse.ArgumentParser(prog="python -m dynsens.case.schema", description=__doc__,
                                 formatter_class=argparse.RawDescriptionHelpFormatter)
    g = ap.add_mutually_exclusive_group()
    g.add_argument("--write", action="store_true", help="write docs/case.schema.json and docs/case-reference.md")
    g.add_argument("--check", action="store_true", help="exit 1 when the files are out of date")
    args = ap.parse_args(argv)
    files = generated()
    if args.write:
        for path, text in files.items():
            path.write_text(text, encoding="utf-8")
            print(f"written: {path}")
        return 0
    if args.check:
        stale = [str(p) for p, text in files.items() if not p.exists() or p.read_text(encoding="utf-8") != text]
        if stale:
            print(f"out of date: {', '.join(stale)}; run python -m dynsens.case.schema --write", file=sys.stderr)
            return 1
        print("case reference and schema are up to date")
        return 0
    print(files[SCHEMA_PATH], end="")
    return 0


if __name__ == "__main__":
    sys.exit(main())
