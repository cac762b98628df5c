"""``dynsens info``: what a result file holds and what produced it."""
from __future__ import annotations

import json
from typing import Any

import click
import h5py
import numpy as np

from ..errors import DynsensError
from .main import cli
from .options import verbosity_options


class NotAResultError(DynsensError, ValueError):
    """The file is not a dynsens result file."""


def _text(v: Any) -> str:
    return v.decode() if isinstance(v, bytes) else str(v)


def _kind(f: h5py.File) -> str:
    if "optimization" in f:
        return "optimization"
    if "modes" in f:
        return "modes"
    if "study" in f or "designs" in f:
        return "study"
    return "simulation"


def describe(path: str) -> str:
    """The summary ``dynsens info`` prints (raises NotAResultError for another file)."""
    try:
        f = h5py.File(path, "r")
    except OSError as exc:
        raise NotAResultError(f"{path}: not an HDF5 file ({exc})") from None
    with f:
        a = f.attrs
        if "dynsens_version" not in a:
            raise NotAResultError(f"{path}: not a dynsens result file (no dynsens_version attribute)")
        lines = [f"{path}: dynsens {_kind(f)} file, status {_text(a.get('status', '?'))}"
                 + (f" ({_text(a['message'])})" if _text(a.get("message", "")) else ""),
                 f"  created {_text(a.get('created', '?'))} by dynsens {_text(a['dynsens_version'])}",
                 f"  case {_text(a.get('case_source', '?'))}, sha256 {_text(a.get('case_sha256', 'not recorded'))}"]
        if "provenance_command" in a:
            versions = json.loads(_text(a["provenance_versions"]))
            lines += [f"  command: {_text(a['provenance_command'])}",
                      f"  host {_text(a['provenance_host'])}, time zone {_text(a['provenance_timezone'])}",
                      f"  git: {_text(a['provenance_git']) or 'not a checkout'}",
                      "  versions: " + ", ".join(f"{k} {v}" for k, v in versions.items())]
        else:
            lines.append("  provenance: not recorded (a file from before dynsens recorded it)")
        lines += _contents(f)
    return "\n".join(lines)


def _contents(f: h5py.File) -> list[str]:
    out: list[str] = []
    if "design/names" in f:
        names = [_text(n) for n in f["design/names"][()]]
        out.append(f"  design: {len(names)} variable(s)" + (f": {', '.join(names)}" if len(names) <= 8 else ""))
    if isinstance(f.get("load_cases"), h5py.Group):   # simulate of a case with load cases
        for name, g in f["load_cases"].items():
            out.append(f"  load case {name} (/load_cases/{name}): status {_text(g.attrs.get('status', ''))}")
            out += ["  " + line for line in _run_contents(g)]
        return out
    return out + _run_contents(f)


def _run_contents(f: h5py.Group) -> list[str]:
    """Time, histories, responses and optimization of one run's group (the file's root, or a load case's)."""
    out: list[str] = []
    if "time" in f:
        t = f["time"][()]
        out.append(f"  time: {t.size} instants, {t[0]:.6g} to {t[-1]:.6g} s")
    if "state" in f:
        out.append("  histories: " + ", ".join(f"{k} {f['state'][k].shape}" for k in f["state"]))
    if "responses" in f:
        out.append("  responses:")
        for name in f["responses"]:
            g = f["responses"][name]
            unit = _text(g.attrs.get("unit", ""))
            value = float(np.real(g["value"][()])) if "value" in g else float("nan")
            grad = "with gradient" if "gradient" in g else "no gradient"
            missing = _text(g.attrs.get("missing", ""))
            out.append(f"    {name} = {value:.8g}{' ' + unit if unit else ''} ({grad})"
                       + (f" MISSING: {missing}" if missing else ""))
    if "optimization/summary" in f:
        s = f["optimization/summary"]
        best = int(s.attrs["best"])
        k = list(s["start"][()]).index(best)
        out.append(f"  optimization: {len(s['start'])} start(s), best {best}: f = {float(s['f'][k]):.8g}, "
                   f"feasible {bool(s['feasible'][k])}, converged {bool(s['success'][k])}, "
                   f"{int(s['nit'][k])} iterations")
    if "verification" in f:
        v = f["verification"]
        out.append(f"  verification: {'passed' if bool(v.attrs['passed']) else 'NOT passed'}"
                   + (f" after {len(v['rounds/f']) - 1} tightening round(s)" if "rounds" in v else "")
                   + _per_load_case(v))
    if "modes/frequencies" in f:
        fr = f["modes/frequencies"][()]
        out.append("  modes: " + ", ".join(f"{x:.6g}" for x in fr) + " Hz")
    return out


def _per_load_case(v: h5py.Group) -> str:
    """', in load cases impact (passed), gust (NOT passed)' for a verification over load cases."""
    if "load_cases" not in v.attrs:
        return ""
    failing = set(json.loads(_text(v.attrs["failing"])))
    return ", in load cases " + ", ".join(f"{n} ({'NOT passed' if n in failing else 'passed'})"
                                         for n in json.loads(_text(v.attrs["load_cases"])))


@cli.command("info")
@click.argument("result", type=click.Path(exists=True, dir_okay=False))
@verbosity_options
def info(result: str) -> None:
    """Print what a dynsens result file holds and what produced it (versions, git commit,
    command, host, time zone, the case's SHA-256)."""
    click.echo(describe(result))
