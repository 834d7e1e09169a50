"""Which study and which input files a result came from: the fingerprint ``analyze`` records.

``roboisf analyze`` writes :func:`study_fingerprint` into ``summary.json`` (``"fingerprint"``):
the size and SHA-256 of ``study.toml`` and of every file it names, keyed by the study key that
names the file (``runs.robot.scan``) — never by a path, so the same study gives the same bytes in
any folder. A command that reads results back (``compensate --results``) calls
:func:`check_results` and refuses results of another study, or of a study whose files changed
since (a new scan, another toolpath), naming the first file that differs; before, results carried
only the study's name and the results of another study of the same geometry were accepted.
"""

from __future__ import annotations

import hashlib
import json
from collections.abc import Iterator, Mapping
from pathlib import Path
from typing import Any

from roboisf.errors import InputError
from roboisf.study.spec import Study

__all__ = ["FORMAT", "check_results", "study_fingerprint"]

#: the fingerprint's format tag in ``summary.json``
FORMAT = "roboisf-fingerprint/1"


def _files(study: Study) -> Iterator[tuple[str, Path]]:
    """(study key, file) of ``study.toml`` and every file it names."""
    yield "study.toml", study.root / "study.toml"
    if study.tool.compliance is not None:
        yield "tool.compliance", study.tool.compliance
    if study.holder.compliance is not None:
        yield "tool_holder.compliance", study.holder.compliance
    if study.robot is not None and Path(study.robot.model).is_file():
        yield "robot.model", Path(study.robot.model)
    for name in sorted(study.runs):
        r = study.runs[name]
        key = f"runs.{name}"
        yield f"{key}.toolpath", r.toolpath
        yield f"{key}.forces.file", r.forces.file
        yield f"{key}.scan", r.scan
        if r.joints is not None:
            yield f"{key}.joints", r.joints
        if r.thickness is not None:
            yield f"{key}.thickness", r.thickness


def _digest(path: Path) -> dict[str, Any]:
    with open(path, "rb") as fh:
        h = hashlib.file_digest(fh, "sha256")
    return {"size": path.stat().st_size, "sha256": h.hexdigest()}


def study_fingerprint(study: Study) -> dict[str, Any]:
    """The fingerprint of ``study``: ``{"format", "study", "id", "files": {key: {"size",
    "sha256"}}}``; ``id`` is the SHA-256 of the sorted ``files`` (hex, 64 characters).

    Reads every input file once (≈ 1 GB/s).
    """
    files = {key: _digest(p) for key, p in _files(study)}
    blob = json.dumps(files, sort_keys=True, separators=(",", ":")).encode()
    return {
        "format": FORMAT,
        "study": study.name,
        "id": hashlib.sha256(blob).hexdigest(),
        "files": files,
    }


def check_results(study: Study, results: str | Path) -> None:
    """Refuse ``results`` (an ``analyze`` output folder) unless its ``summary.json`` carries the
    fingerprint of ``study`` as its files are now.

    Raises
    ------
    InputError
        naming ``summary.json`` and, when the fingerprints differ, the first study key whose file
        differs and what to do (give the results of this study, or analyse it again).
    """
    f = Path(results) / "summary.json"
    again = f"run `roboisf analyze {study.root.name}` again, or give the results of this study"
    try:
        data = json.loads(f.read_text(encoding="utf-8"))
    except FileNotFoundError:
        raise InputError(
            f"no summary.json: these results cannot be matched to a study; {again}", file=results
        ) from None
    except (OSError, UnicodeDecodeError, ValueError) as e:
        raise InputError(f"not a readable summary ({e}); {again}", file=f) from None
    fp = data.get("fingerprint") if isinstance(data, Mapping) else None
    if not isinstance(fp, Mapping) or fp.get("format") != FORMAT:
        raise InputError(
            "these results carry no study fingerprint (written by an older roboisf, or "
            f"edited): they cannot be matched to the study; {again}",
            file=f,
            field="fingerprint",
        )
    now = study_fingerprint(study)
    if fp.get("id") == now["id"]:
        return
    was = fp.get("files") if isinstance(fp.get("files"), Mapping) else {}
    assert isinstance(was, Mapping)
    changed = [k for k in now["files"] if was.get(k) != now["files"][k]]
    changed += [k for k in was if k not in now["files"]]
    other = fp.get("study")
    whose = (
        f"come from the study {other!r}, not {study.name!r}"
        if isinstance(other, str) and other != study.name
        else f"come from another version of the study {study.name!r}"
    )
    what = f"{changed[0]} differs" if changed else "its files differ"
    more = f" (and {len(changed) - 1} more)" if len(changed) > 1 else ""
    raise InputError(
        f"these results {whose}: {what}{more} since they were computed; {again}",
        file=f,
        field="fingerprint",
    )
