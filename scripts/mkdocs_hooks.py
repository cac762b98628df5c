"""MkDocs hook: the documents are written for the repository; the site is built from them.

Every document links by repository-relative paths, which work on a repository host and which
tests/test_docs.py checks.  The site's pages live in ``docs/``; this hook

* adds the top-level documents as pages: README.md as the home page, CHANGELOG.md,
  CONTRIBUTING.md and BENCHMARKS.md;
* copies every other repository file a document links to (a case, a script, LICENSE) into the
  site under ``repo/``, so that its link works there too;
* rewrites each document's links from repository paths to the site's paths.

Used by ``mkdocs.yml`` (``hooks:``); ``make docs`` builds the site.
"""
from __future__ import annotations

import posixpath
import re
from pathlib import Path
from typing import Any

from mkdocs.structure.files import File, Files

REPO = Path(__file__).resolve().parents[1]
# top-level documents -> their page in the site
TOP_LEVEL = {"README.md": "index.md", "CHANGELOG.md": "changelog.md", "CONTRIBUTING.md": "contributing.md",
             "BENCHMARKS.md": "benchmarks.md"}
LINK = re.compile(r"(\]\()([^)\s]+)(\))")
FENCE = re.compile(r"^(```|~~~)")
_site_of_repo: dict[str, str] = {}     # repository path -> site path (src_uri), filled by on_files
_repo_of_site: dict[str, str] = {}


def _outside_fences(text: str, fix: Any) -> str:
    out, fenced = [], False
    for line in text.splitlines(keepends=True):
        if FENCE.match(line):
            fenced = not fenced
        out.append(line if fenced else LINK.sub(fix, line))
    return "".join(out)


def _targets(repo_path: str, text: str) -> set[str]:
    """The repository paths that a document's relative links point to."""
    found: set[str] = set()

    def note(m: re.Match[str]) -> str:
        target = m.group(2).split("#", 1)[0]
        if target and not re.match(r"^[a-z]+:", target):
            found.add(posixpath.normpath(posixpath.join(posixpath.dirname(repo_path), target)))
        return m.group(0)
    _outside_fences(text, note)
    return found


def on_files(files: Files, config: Any) -> Files:
    docs_dir = Path(config["docs_dir"]).resolve()
    prefix = docs_dir.relative_to(REPO).as_posix()
    _site_of_repo.clear()
    _repo_of_site.clear()
    for f in files:
        _site_of_repo[f"{prefix}/{f.src_uri}"] = f.src_uri
    for repo_path, site_path in TOP_LEVEL.items():
        files.append(File.generated(config, site_path, abs_src_path=str(REPO / repo_path)))
        _site_of_repo[repo_path] = site_path
    documents = {path: site for path, site in _site_of_repo.items() if path.endswith(".md")}
    _repo_of_site.update({site: path for path, site in documents.items()})
    linked: set[str] = set()
    for repo_path in documents:
        linked |= _targets(repo_path, (REPO / repo_path).read_text(encoding="utf-8"))
    for path in sorted(linked - set(_site_of_repo)):
        if (REPO / path).is_file():
            site_path = f"repo/{path}"
            files.append(File.generated(config, site_path, abs_src_path=str(REPO / path)))
            _site_of_repo[path] = site_path
    return files


def on_page_markdown(markdown: str, page: Any, config: Any, files: Files) -> str:
    repo_path = _repo_of_site.get(page.file.src_uri)
    if repo_path is None:
        return markdown
    here = posixpath.dirname(page.file.src_uri)

    def fix(m: re.Match[str]) -> str:
        target, _, anchor = m.group(2).partition("#")
        if not target or re.match(r"^[a-z]+:", target):
            return m.group(0)
        path = posixpath.normpath(posixpath.join(posixpath.dirname(repo_path), target))
        site = _site_of_repo.get(path)
        if site is None:        # a folder: no page to link to
            return m.group(0)
        new = posixpath.relpath(site, here or ".")
        return m.group(1) + new + ("#" + anchor if anchor else "") + m.group(3)
    return _outside_fences(markdown, fix)
