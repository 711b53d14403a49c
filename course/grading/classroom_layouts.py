"""Where each student's files are in a folder of a whole class's submissions.

Three layouts are read, and may be mixed in one folder:

* **one folder or zip per student**: the student is the folder's (or zip's) name;
* a **Gradescope export** ("Export Submissions"): a folder holding
  ``submission_metadata.yml`` and one ``submission_<id>/`` folder per submission; the
  metadata names the students (``:submitters:`` with ``:name:`` and ``:sid:``). It may be
  the folder given or one folder inside it;
* **flat files of a learning-management system**, each named for its student:
  Canvas (``doejane_12345_67890_lab4_march.py``, ``doejane_LATE_12345_67890_...``),
  Moodle (``Jane Doe_12345_assignsubmission_file_lab4_march.py``, or a folder
  ``Jane Doe_12345_assignsubmission_file_/`` per student) and Blackboard
  (``Lab 4_jdoe_attempt_2026-03-01-12-00-00_lab4_march.py``: the latest attempt is taken).

Nothing here writes anywhere: :func:`find_submissions` only lists files. Names starting
with ``.`` and ``__MACOSX`` folders are ignored, as zip tools and file managers leave them.
"""

from __future__ import annotations

import re
from collections import defaultdict
from dataclasses import dataclass, field
from pathlib import Path

GRADESCOPE_METADATA = "submission_metadata.yml"

CANVAS = re.compile(
    r"^(?P<student>[A-Za-z0-9.\-]+?)(?:_LATE)?_(?P<sid>\d+)_(?P<sub>\d+)_"
    r"(?P<name>.+)$"
)
MOODLE = re.compile(
    r"^(?P<student>.+?)_(?P<sid>\d+)_assignsubmission_(?:file|onlinetext)_"
    r"(?P<name>.*)$"
)
BLACKBOARD = re.compile(
    r"^(?P<assignment>.+?)_(?P<student>[^_]+)_attempt_"
    r"(?P<time>\d{4}-\d{2}-\d{2}-\d{2}-\d{2}-\d{2})(?:_(?P<name>.+))?$"
)
KIND_NAMES = {
    "folder": "folders",
    "zip": "zips",
    "gradescope": "Gradescope export",
    "canvas": "Canvas files",
    "moodle": "Moodle files",
    "blackboard": "Blackboard files",
}


@dataclass
class Submission:
    """One student's submission: ``files`` maps each file's name inside the submission (as
    the student handed it in) to where it lies now."""

    student: str
    sid: str
    kind: str  # folder | zip | gradescope | canvas | moodle | blackboard
    source: str  # where it was found, relative to the class folder
    files: dict[str, Path] = field(default_factory=dict)

    @property
    def key(self) -> str:
        """The row's name in the gradebook: the student, and the id where there is one."""
        return f"{self.student} ({self.sid})" if self.sid else self.student


def _ignored(name: str) -> bool:
    return name.startswith(".") or name == "__MACOSX"


def _tree(folder: Path) -> dict[str, Path]:
    """Every file below ``folder`` (links included, never followed), by relative name."""
    found = {}
    for path in sorted(folder.rglob("*")):
        rel = path.relative_to(folder)
        if any(_ignored(part) for part in rel.parts):
            continue
        if path.is_symlink() or path.is_file():
            found[rel.as_posix()] = path
    return found


def read_gradescope_metadata(path: Path) -> dict[str, tuple[str, str]]:
    """``submission_<id>`` -> (the submitters' names, their student ids), each joined with
    " & " for a group submission. Gradescope writes the keys as Ruby symbols
    (``:submitters:``); they are read with or without the colon."""
    import yaml

    data = yaml.load(path.read_text(errors="replace"), Loader=yaml.BaseLoader) or {}
    table = {}
    for folder, entry in data.items() if isinstance(data, dict) else ():
        entry = (
            {str(k).lstrip(":"): v for k, v in (entry or {}).items()}
            if isinstance(entry, dict)
            else {}
        )
        people = entry.get("submitters") or []
        names, sids = [], []
        for person in people if isinstance(people, list) else ():
            if isinstance(person, dict):
                person = {str(k).lstrip(":"): v for k, v in person.items()}
                names.append(str(person.get("name") or person.get("email") or "").strip())
                sids.append(str(person.get("sid") or "").strip())
        table[str(folder)] = (" & ".join(n for n in names if n), " & ".join(s for s in sids if s))
    return table


def _gradescope(export: Path, class_folder: Path) -> list[Submission]:
    table = read_gradescope_metadata(export / GRADESCOPE_METADATA)
    found = []
    for folder in sorted(p for p in export.iterdir() if p.is_dir() and not _ignored(p.name)):
        if not folder.name.startswith("submission_"):
            continue
        name, sid = table.get(folder.name, ("", ""))
        found.append(
            Submission(
                student=name or folder.name,
                sid=sid,
                kind="gradescope",
                source=folder.relative_to(class_folder).as_posix(),
                files=_tree(folder),
            )
        )
    return found


def _lms_match(name: str):
    """(kind, student, sid, file name) for a file named by an LMS export, else None."""
    for kind, pattern in (("moodle", MOODLE), ("blackboard", BLACKBOARD), ("canvas", CANVAS)):
        match = pattern.match(name)
        if match:
            sid = match.groupdict().get("sid") or ""
            rest = match.group("name") or (name if kind != "blackboard" else "")
            return kind, match.group("student").strip(), sid, rest
    return None


def find_submissions(folder) -> tuple[list[Submission], list[str]]:
    """Every submission in the class folder ``folder``, sorted by student, and the names of
    the entries that name no student (ignored). Raises ValueError when the folder holds no
    submission at all, saying what it holds instead."""
    folder = Path(folder)
    if (folder / GRADESCOPE_METADATA).is_file():
        subs = _gradescope(folder, folder)
        return sorted(subs, key=lambda s: (s.key, s.source)), []
    subs: list[Submission] = []
    flat: dict[tuple[str, str, str], dict[str, tuple[str, Path]]] = defaultdict(dict)
    ignored = []
    for entry in sorted(folder.iterdir()):
        if _ignored(entry.name):
            continue
        if entry.is_dir() and not entry.is_symlink():
            if (entry / GRADESCOPE_METADATA).is_file():
                subs += _gradescope(entry, folder)
                continue
            match = _lms_match(entry.name)  # Moodle's folder per student
            if match and match[0] == "moodle":
                subs.append(
                    Submission(
                        student=match[1],
                        sid=match[2],
                        kind="moodle",
                        source=entry.name,
                        files=_tree(entry),
                    )
                )
            else:
                subs.append(
                    Submission(
                        student=entry.name,
                        sid="",
                        kind="folder",
                        source=entry.name,
                        files=_tree(entry),
                    )
                )
            continue
        if not entry.is_file() or entry.is_symlink():
            ignored.append(entry.name)
            continue
        match = _lms_match(entry.name)
        if match:
            kind, student, sid, name = match
            attempt = ""
            if kind == "blackboard":
                attempt = BLACKBOARD.match(entry.name).group("time")
            flat[(kind, student, sid)][f"{attempt}/{name}"] = (attempt, entry)
        elif entry.suffix.lower() == ".zip":
            subs.append(
                Submission(
                    student=entry.stem,
                    sid="",
                    kind="zip",
                    source=entry.name,
                    files={entry.name: entry},
                )
            )
        else:
            ignored.append(entry.name)
    for (kind, student, sid), files in sorted(flat.items()):
        latest = max(attempt for attempt, _ in files.values())
        chosen = {
            name.split("/", 1)[1]: path
            for name, (attempt, path) in files.items()
            if attempt == latest
        }
        subs.append(
            Submission(
                student=student,
                sid=sid,
                kind=kind,
                source=", ".join(sorted(p.name for p in chosen.values())),
                files=chosen,
            )
        )
    if not subs:
        what = ", ".join(ignored[:5]) or "nothing"
        raise ValueError(
            f"no submissions in {folder}: expected one folder or zip per "
            f"student, a Gradescope export ({GRADESCOPE_METADATA}) or files "
            f"named for their student by Canvas, Moodle or Blackboard; it holds "
            f"{what}"
        )
    _disambiguate(subs)
    return sorted(subs, key=lambda s: (s.key, s.source)), ignored


def _disambiguate(subs: list[Submission]):
    """Give two submissions of the same student name (and id) distinct keys: the later by
    source gets " #2", and so on, so no row of the gradebook overwrites another."""
    seen: dict[str, int] = defaultdict(int)
    for sub in sorted(subs, key=lambda s: (s.key, s.source)):
        seen[sub.key] += 1
        if seen[sub.key] > 1:
            sub.student = f"{sub.student} #{seen[sub.key]}"


def describe(subs: list[Submission]) -> str:
    """The layout found, in one line: ``3 folders, 2 zips, Gradescope export: 4``."""
    counts: dict[str, int] = defaultdict(int)
    for sub in subs:
        counts[sub.kind] += 1
    return ", ".join(
        f"{KIND_NAMES[kind]}: {n}"
        for kind, n in sorted(counts.items(), key=lambda kv: list(KIND_NAMES).index(kv[0]))
    )
