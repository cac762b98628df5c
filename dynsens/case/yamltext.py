"""Reading a case file's text and YAML safely: encoding, duplicate keys, alias expansion, depth.

PyYAML's ``safe_load`` refuses arbitrary objects but still (a) lets a second ``model:``
silently replace the first, (b) expands a few lines of nested aliases into billions of
entries once the mapping is copied or dumped, and (c) recurses on deep nesting.  This
module composes the node graph first, checks it with the YAML key path of every problem,
and only then constructs the mapping.
"""
from __future__ import annotations

from pathlib import Path
from typing import Any

import yaml

from ..errors import CaseError, Problem

#: largest case file read (bytes); the shipped cases are a few kB
MAX_FILE_BYTES = 10 * 2**20
#: largest number of nodes the mapping may have once aliases are expanded
MAX_EXPANDED_NODES = 200_000
#: deepest nesting of mappings and lists
MAX_DEPTH = 64
_MERGE_TAG = "tag:yaml.org,2002:merge"


def read_case_text(path: Path, source: str) -> str:
    """The file's text, decoded as UTF-8 (a UTF-8 byte-order mark is accepted).

    Raises CaseError for a missing/unreadable file, a file too large, binary data, UTF-16/32
    text or bytes that are not UTF-8, saying what was found and where.
    """
    try:
        size = path.stat().st_size
        if path.is_dir():
            raise CaseError(f"cannot read {source}: expected a case file, found a folder", source)
        if size > MAX_FILE_BYTES:
            raise CaseError(f"expected a case file of at most {MAX_FILE_BYTES // 2**20} MiB, found "
                            f"{size / 2**20:.1f} MiB", source)
        data = path.read_bytes()
    except FileNotFoundError:
        raise CaseError(f"file not found: {source}", source) from None
    except OSError as exc:
        raise CaseError(f"cannot read {source}: {exc.strerror}", source) from None
    return decode_case_bytes(data, source)


def decode_case_bytes(data: bytes, source: str) -> str:
    """UTF-8 text of ``data``, or CaseError naming the encoding found."""
    boms = {b"\xff\xfe\x00\x00": "UTF-32", b"\x00\x00\xfe\xff": "UTF-32",
            b"\xff\xfe": "UTF-16", b"\xfe\xff": "UTF-16"}
    for bom, name in boms.items():
        if data.startswith(bom):
            raise CaseError(f"expected UTF-8 text, found {name} text (byte-order mark): save the file as "
                            "UTF-8", source)
    if b"\x00" in data:
        at = data.index(b"\x00")
        line = data.count(b"\n", 0, at) + 1
        raise CaseError(f"expected UTF-8 text, found binary data (a NUL byte at offset {at}, line "
                        f"{line}): is this a case file?", source)
    try:
        return data.decode("utf-8-sig")
    except UnicodeDecodeError as exc:
        line = data.count(b"\n", 0, exc.start) + 1
        raise CaseError(f"expected UTF-8 text, found byte 0x{data[exc.start]:02x} at offset {exc.start} "
                        f"(line {line}): save the file as UTF-8", source) from None


def _yaml_error(exc: yaml.YAMLError, source: str) -> CaseError:
    mark = getattr(exc, "problem_mark", None)
    where = f" at line {mark.line + 1}, column {mark.column + 1}" if mark else ""
    return CaseError(f"not valid YAML{where}: {getattr(exc, 'problem', None) or exc}", source)


def parse_yaml(text: str, source: str) -> Any:
    """Safe-load ``text`` after checking its node graph (duplicate keys, alias expansion, depth).

    Raises CaseError with the YAML key path of every duplicate key, or with the alias
    expansion / nesting found against the limit.
    """
    try:
        node = yaml.compose(text, Loader=yaml.SafeLoader)
    except yaml.YAMLError as exc:
        raise _yaml_error(exc, source) from None
    except RecursionError:
        raise CaseError(f"expected YAML nested at most {MAX_DEPTH} levels deep, found deeper nesting",
                        source) from None
    if node is None:
        return None
    problems: list[Problem] = []
    _check_graph(node, problems)
    if problems:
        raise CaseError(problems, source)
    try:
        loader = yaml.SafeLoader(text)
        try:
            return loader.construct_document(node)
        finally:
            loader.dispose()
    except yaml.YAMLError as exc:
        raise _yaml_error(exc, source) from None
    except (TypeError, ValueError) as exc:  # e.g. an unhashable (list) key
        raise CaseError(f"not valid as a case: {exc}", source) from None


def _join(path: str, key: str) -> str:
    return f"{path}.{key}" if path else key


def _check_graph(root: yaml.Node, problems: list[Problem]) -> None:
    """Duplicate keys with their paths; expanded size and depth against the limits (iterative)."""
    sizes: dict[int, int] = {}       # expanded node count of each finished collection
    open_: set[int] = set()          # collections being walked (a recursive alias meets one again)
    # frames: (node, path, depth, children-iterator or None)
    stack: list[tuple[yaml.Node, str, int]] = [(root, "", 0)]
    order: list[yaml.Node] = []
    seen: set[int] = set()
    while stack:
        node, path, depth = stack.pop()
        if id(node) in seen:
            continue        # an alias of a node already checked
        seen.add(id(node))
        if depth > MAX_DEPTH:
            problems.append(Problem(path, f"expected nesting at most {MAX_DEPTH} levels deep, found deeper"))
            return
        order.append(node)
        if isinstance(node, yaml.MappingNode):
            first: dict[str, int] = {}
            for key, value in node.value:
                if key.tag == _MERGE_TAG:
                    stack.append((value, path, depth + 1))
                    continue
                name = str(key.value) if isinstance(key, yaml.ScalarNode) else "<complex key>"
                line = key.start_mark.line + 1
                if name in first:
                    problems.append(Problem(_join(path, name), f"expected each key once, found it again at line "
                                                               f"{line} (first at line {first[name]}): the second "
                                                               "entry would silently replace the first"))
                else:
                    first[name] = line
                stack.append((value, _join(path, name), depth + 1))
        elif isinstance(node, yaml.SequenceNode):
            for i, item in enumerate(node.value):
                stack.append((item, f"{path}[{i}]", depth + 1))
    # expanded size, children before parents (post-order over the DAG, recursion refused)
    todo: list[tuple[yaml.Node, bool]] = [(root, False)]
    while todo:
        node, done = todo.pop()
        key = id(node)
        if key in sizes:
            continue
        children = _children(node)
        if done:
            open_.discard(key)
            sizes[key] = 1 + sum(sizes[id(c)] for c in children)
            if sizes[key] > MAX_EXPANDED_NODES:
                problems.append(Problem("", f"expected at most {MAX_EXPANDED_NODES} entries once aliases (*name) "
                                            f"are expanded, found more: the aliases nest too often"))
                return
            continue
        if key in open_:
            problems.append(Problem("", "expected aliases (*name) that refer to finished entries, found one "
                                        "that refers to an entry containing it (a recursive structure)"))
            return
        open_.add(key)
        todo.append((node, True))
        for c in children:
            if id(c) in open_:
                problems.append(Problem("", "expected aliases (*name) that refer to finished entries, found "
                                            "one that refers to an entry containing it (a recursive structure)"))
                return
            if id(c) not in sizes:
                todo.append((c, False))


def _children(node: yaml.Node) -> list[yaml.Node]:
    if isinstance(node, yaml.MappingNode):
        return [n for kv in node.value for n in kv]
    if isinstance(node, yaml.SequenceNode):
        return list(node.value)
    return []
