"""The commands shown in README.md and docs/*.md (the tutorial): find them, run them, compare and rewrite their outputs.

Used by ``test_docs_commands.py`` (the check, run by ``make test``) and ``update_docs.py`` (the update mode).

How a document is read
----------------------
Only fenced blocks opened by a bare fence or one tagged ``console``, ``shell``, ``sh`` or ``bash`` hold
commands; ``json``, ``text`` and every other tag are left alone (show a file or an output with no command
as ``text``).

* A block with ``$ `` lines is a *session*: each ``$ `` line starts a command, and the lines up to the
  next ``$ `` line (or the end of the block) are exactly what that command prints (stdout and stderr
  together), trailing blank lines aside.
* A block without ``$ `` lines is a *command list*: every line that is neither blank nor a ``#`` comment
  starts a command; its output is not shown, so only its exit status is checked.

A command goes on over the next lines while it ends with ``\\``, has an open quote, or has an open
heredoc (``<<'EOF'`` ... ``EOF``). A trailing ``# comment`` is not part of the command's *key* (the text
by which ``EXEMPT`` in the test names it). Every command must exit with status 0: a document that shows
a failure writes ``$ CMD; echo "exit code $?"`` and shows the status line.

A line ``...`` in an output stands for one or more lines left out. Nothing else is a wildcard.

Normalisations (applied to both sides before comparing, and nothing else is)
-----------------------------------------------------------------------------
1. trailing whitespace of each line, and leading and trailing blank lines of an output, are dropped;
2. the temporary folder the commands run in is written as a relative path (``/tmp/xyz/plan.json`` ->
   ``plan.json``), as if the command had run from the repository root;
3. a printed zero with a minus sign (``-0.00``, ``-0.000``, ``-0``) reads as the same zero without it
   (``" 0.00"``, the sign's column kept): the sign of a value that rounds to zero comes from noise of
   order 1e-16 (BLAS, platform), not from the result;
4. wall-clock times (``8 nodes expanded in 2.51 s``) read as ``<t>``;
5. two lines that differ only in decimal numbers match when every one differs by at most one unit of
   its last printed digit (``0.339`` / ``0.340``; integers and exponents are exact): a value on a
   rounding boundary may round either way on another CPU's BLAS kernels; more is a change.

Where the commands run
----------------------
In a fresh temporary folder per document holding a copy of ``examples/`` and a link ``.venv`` to the
running interpreter's environment, with ``COLUMNS=120`` (tables and reports wrap the same way
everywhere), UTF-8 output, no colour, ``MPLBACKEND=Agg`` and the environment's ``bin`` first on
``PATH``, stdin closed; ``bash -c`` runs each command, and the commands of a document run in the
order the document gives them (a later command may read a file an earlier one wrote), so the
repository is never written to.
"""

from __future__ import annotations

import difflib
import os
import re
import shutil
import subprocess
import sys
import tempfile
import time
from collections.abc import Iterable, Iterator, Sequence
from dataclasses import dataclass, field
from pathlib import Path

REPO = Path(__file__).resolve().parents[2]
# the documents whose commands are run: the README and every page of docs/
DOCS = ("README.md", *sorted(p.relative_to(REPO).as_posix() for p in (REPO / "docs").glob("*.md")))
COLUMNS = 120
COMMAND_TIMEOUT = 900.0
ELLIPSIS = "..."
SHELL_TAGS = {"", "console", "shell", "sh", "bash"}
# programs whose commands the test runs; any other command must be listed in EXEMPT (test_docs_commands.py)
RUNNABLE = {".venv/bin/ctp", "ctp", ".venv/bin/python", "cat"}
COPIED = ("examples",)  # what a fresh workspace holds besides .venv

_FENCE = re.compile(r"^(`{3,})\s*([\w+-]*)\s*$")
_HEREDOC = re.compile(r"<<-?\s*(['\"]?)([A-Za-z_]\w*)\1")


@dataclass
class Command:
    """One command of a document: where it is, what bash runs, and the output the document shows."""

    doc: str  # path relative to the repository
    line: int  # 1-based line of its first line in the document
    text: str  # what bash runs (prompt removed, continuation lines kept)
    shown: list[str] | None  # the output lines shown (None in a command list: output not shown)
    out_start: int = 0  # 0-based document lines [out_start, out_end) holding the shown output
    out_end: int = 0

    @property
    def key(self) -> str:
        """The command without a trailing comment, its lines joined by newlines (EXEMPT's keys)."""
        return strip_comment(self.text)

    @property
    def program(self) -> str:
        words = self.key.split()
        return words[0] if words else ""

    @property
    def ident(self) -> str:
        return f"{Path(self.doc).name}:{self.line}"


@dataclass
class Result:
    returncode: int
    output: list[str]
    seconds: float


def _scan(line: str, state: str | None) -> tuple[str | None, int | None]:
    """One line read by bash's quoting rules (' " and backslash) from the open quote ``state``:
    the quote still open at its end, and where an unquoted ``# comment`` starts (None: none)."""
    i = 0
    while i < len(line):
        c = line[i]
        if state is None:
            if c == "\\":
                i += 1
            elif c in "'\"":
                state = c
            elif c == "#" and (i == 0 or line[i - 1].isspace()):
                return None, i  # the rest of the line is a comment
        elif state == "'":
            if c == "'":
                state = None
        elif c == "\\":
            i += 1
        elif c == '"':
            state = None
        i += 1
    return state, None


def _quote_state(text: str) -> str | None:
    """The quote left open at the end of ``text`` (None if none)."""
    state: str | None = None
    for line in text.split("\n"):
        state, _ = _scan(line, state)
    return state


def strip_comment(text: str) -> str:
    """``text`` without trailing ``# comments`` (outside quotes) on each line, trailing spaces dropped."""
    out = []
    state: str | None = None
    for line in text.split("\n"):
        state, cut = _scan(line, state)
        out.append(line[:cut].rstrip())
    return "\n".join(out).strip()


def _command_end(lines: Sequence[str], start: int, first: str) -> int:
    """Index after the last line of the command whose first line (prompt removed) is ``first``."""
    text = first
    i = start + 1
    while True:
        heredocs = [m.group(2) for m in _HEREDOC.finditer(text)]
        state = _quote_state(text)
        if heredocs and state is None:
            for delimiter in heredocs:
                while i < len(lines) and lines[i] != delimiter:
                    i += 1
                i += 1
            return min(i, len(lines))
        if state is None and not text.endswith("\\"):
            return i
        if i >= len(lines):
            return i
        text += "\n" + lines[i]
        i += 1


def _blocks(lines: Sequence[str]) -> Iterator[tuple[str, int, int]]:
    """(tag, first content line, end) of each fenced block; an unclosed fence runs to the end."""
    i = 0
    while i < len(lines):
        m = _FENCE.match(lines[i])
        if not m:
            i += 1
            continue
        fence, tag = m.group(1), m.group(2).lower()
        j = i + 1
        while j < len(lines) and not (lines[j].startswith(fence) and lines[j].strip() == fence):
            j += 1
        yield tag, i + 1, j
        i = j + 1


def parse_commands(doc: str, text: str) -> list[Command]:
    """Every command of the shell blocks of a document (``doc`` names it in the results)."""
    lines = text.split("\n")
    commands: list[Command] = []
    for tag, start, end in _blocks(lines):
        if tag not in SHELL_TAGS:
            continue
        body = lines[start:end]
        session = any(line.startswith("$ ") or line == "$" for line in body)
        i = 0
        current: Command | None = None
        while i < len(body):
            line = body[i]
            if session and (line.startswith("$ ") or line == "$"):
                stop = _command_end(body, i, line[2:])
                current = Command(doc, start + i + 1, "\n".join([line[2:], *body[i + 1:stop]]), [],
                                  start + stop, start + stop)
                commands.append(current)
                i = stop
                continue
            if session:
                if current is None:
                    raise ValueError(f"{doc}:{start + i + 1}: output before the first '$ ' command of its block")
                current.out_end = start + i + 1
                i += 1
                continue
            if not line.strip() or line.lstrip().startswith("#"):
                i += 1
                continue
            stop = _command_end(body, i, line)
            commands.append(Command(doc, start + i + 1, "\n".join(body[i:stop]), None))
            i = stop
    for c in commands:
        if c.shown is not None:
            shown = lines[c.out_start:c.out_end]
            while shown and not shown[-1].strip():
                shown.pop()
            c.out_end = c.out_start + len(shown)
            c.shown = shown
    return commands


# ---------------------------------------------------------------------------------------------- normalising

_NEG_ZERO = re.compile(r"(?<![\w.])-(?=0(?:\.0*)?(?![\d.eE]))")
_WALL_CLOCK = re.compile(r"(nodes expanded in )\d+(?:\.\d+)? s\b")


def relative(line: str, workspace: Iterable[str] = ()) -> str:
    """``line`` with the workspace's absolute path written relative to it (normalisation 2), right-stripped."""
    for ws in workspace:
        line = line.replace(ws + os.sep, "").replace(ws, ".")
    return line.rstrip()


def normalise_line(line: str, workspace: Iterable[str] = ()) -> str:
    line = relative(line, workspace)
    line = _NEG_ZERO.sub(" ", line)
    line = _WALL_CLOCK.sub(r"\1<t> s", line)
    return line.rstrip()


def normalise(lines: Sequence[str], workspace: Iterable[str] = ()) -> list[str]:
    ws = list(workspace)
    out = [normalise_line(line, ws) for line in lines]
    while out and not out[0]:
        out.pop(0)
    while out and not out[-1]:
        out.pop()
    return out


# ---------------------------------------------------------------------------------------------- matching

def _segments(shown: Sequence[str]) -> tuple[list[list[str]], bool, bool]:
    """The runs of shown lines between ``...`` lines; whether lines are left out before / after them."""
    segments: list[list[str]] = [[]]
    for line in shown:
        if line.strip() == ELLIPSIS:
            segments.append([])
        else:
            segments[-1].append(line)
    lead = len(segments) > 1 and not segments[0]
    trail = len(segments) > 1 and not segments[-1]
    return [s for s in segments if s], lead, trail


_NUMBER = re.compile(r"[-+]?\d+(?:\.(\d+))?(?:[eE][-+]?\d+)?")


def lines_equal(shown: str, actual: str) -> bool:
    """Equal lines, up to one unit in the last printed digit of each number (normalisation 5)."""
    if shown == actual:
        return True
    a, b = list(_NUMBER.finditer(shown)), list(_NUMBER.finditer(actual))
    if len(a) != len(b) or _NUMBER.sub("#", shown) != _NUMBER.sub("#", actual):
        return False
    for x, y in zip(a, b, strict=True):
        if x.group(0) == y.group(0):
            continue
        if x.group(1) is None or y.group(1) is None or "e" in (x.group(0) + y.group(0)).lower():
            return False  # counts, indices and exponents are exact
        unit = 10.0 ** -max(len(x.group(1) or ""), len(y.group(1) or ""))
        if abs(float(x.group(0)) - float(y.group(0))) > 1.001 * unit:
            return False
    return True


def _run_equal(act: Sequence[str], seg: Sequence[str]) -> bool:
    return len(act) == len(seg) and all(lines_equal(s_, a_) for s_, a_ in zip(seg, act, strict=True))


def _placement(segments: Sequence[Sequence[str]], lead: bool, trail: bool, act: Sequence[str]) -> bool:
    pos = 0  # first line of ``act`` not used yet
    for k, seg in enumerate(segments):
        lo = pos + (1 if (k > 0 or lead) else 0)  # a '...' before the run leaves out one line or more
        if k == 0 and not lead:
            candidates: Iterable[int] = [0]
        elif k == len(segments) - 1 and not trail:
            candidates = [len(act) - len(seg)]
        else:
            candidates = range(lo, len(act) - len(seg) + 1)
        found = next((p for p in candidates if p >= lo and _run_equal(act[p:p + len(seg)], seg)), None)
        if found is None:
            return False
        pos = found + len(seg)
    return pos < len(act) if trail else pos == len(act)


def matches(shown: Sequence[str], actual: Sequence[str], workspace: Iterable[str] = ()) -> bool:
    """Whether ``actual`` is ``shown`` with each ``...`` line standing for one or more lines (normalised)."""
    segments, lead, trail = _segments(normalise(shown))
    act = normalise(actual, workspace)
    if not segments:
        return len(act) >= 1 if (lead or trail) else not act
    return _placement(segments, lead, trail, act)


# ---------------------------------------------------------------------------------------------- rewriting

def _key(line: str) -> str:
    """What names a line: a table row's first cell, else its leading words up to the first number."""
    s = line.strip()
    if s.startswith("│"):
        return s.split("│")[1].strip() if s.count("│") > 1 else ""
    words = []
    for w in s.split():
        if re.search(r"[\d\[\](=]", w):
            break
        words.append(w)
    return " ".join(words)


def _score(doc_lines: Sequence[str], act_lines: Sequence[str]) -> float:
    total = 0.0
    for d, a in zip(doc_lines, act_lines, strict=True):
        if normalise_line(d) == normalise_line(a):
            total += 4.0
            continue
        if _key(d) == _key(a):
            total += 2.0
        total += difflib.SequenceMatcher(None, d, a, autojunk=False).ratio()
    return total


def _keep_equal(old: Sequence[str], new: Sequence[str]) -> list[str]:
    """``new``, keeping the old text of each line that normalises the same (no churn in timings)."""
    return [o if normalise_line(o) == normalise_line(n) else n for o, n in zip(old, new, strict=False)] + \
        list(new[len(old):])


def rewrite(shown: Sequence[str], actual: Sequence[str], workspace: Iterable[str] = ()) -> list[str]:
    """The output block to show for ``actual``, trimmed where ``shown`` is trimmed.

    An untrimmed block becomes the whole output. In a trimmed one each run of shown lines is placed
    where the output has the lines most like it (same table row or report line first, then the most
    similar text) and replaced by those lines; a head run keeps its length from the first line, a tail
    run runs from its best first line to the end; ``...`` stays between runs that are apart and goes
    where two runs now meet.
    """
    ws = list(workspace)
    act = [relative(a, ws) for a in actual]
    while act and not act[0]:
        act.pop(0)
    while act and not act[-1]:
        act.pop()
    if matches(shown, act):
        return list(shown)
    segments, lead, trail = _segments(shown)
    if not segments or (len(segments) == 1 and not lead and not trail):
        return _keep_equal(list(shown), act)
    placed: list[tuple[int, int, list[str]]] = []
    pos = 0
    for k, seg in enumerate(segments):
        n = len(seg)
        first, last = k == 0 and not lead, k == len(segments) - 1 and not trail
        lo = pos  # a run may now follow the previous one directly: its '...' is then dropped
        if first:
            start, stop = 0, min(n, len(act))
        elif last:
            options = range(lo, len(act))
            if not options:
                return act
            start = max(options, key=lambda p: (_score(seg[:1], act[p:p + 1]), -p))
            stop = len(act)
        else:
            options = range(lo, len(act) - n + 1)
            if not options:
                return act
            start = max(options, key=lambda p: (_score(seg, act[p:p + n]), -p))
            stop = start + n
        placed.append((start, stop, seg))
        pos = stop
    out: list[str] = []
    prev = 0
    for k, (start, stop, seg) in enumerate(placed):
        if start > prev or (k == 0 and lead):
            out.append(ELLIPSIS)
        out.extend(_keep_equal(seg, act[start:stop]))
        prev = stop
    if trail and prev < len(act):
        out.append(ELLIPSIS)
    return out


# ---------------------------------------------------------------------------------------------- running

@dataclass
class Workspace:
    """A temporary folder in which one document's commands run, in the document's order."""

    root: Path
    results: dict[int, Result] = field(default_factory=dict)

    @classmethod
    def create(cls) -> Workspace:
        root = Path(tempfile.mkdtemp(prefix="ctp-docs-"))
        for name in COPIED:
            shutil.copytree(REPO / name, root / name, ignore=shutil.ignore_patterns("__pycache__"))
        (root / ".venv").symlink_to(Path(sys.prefix))
        return cls(root)

    @property
    def names(self) -> list[str]:
        return sorted({str(self.root), os.path.realpath(self.root)}, key=len, reverse=True)

    def run(self, command: Command) -> Result:
        env = {k: v for k, v in os.environ.items() if k not in {"FORCE_COLOR", "TTY_COMPATIBLE", "TTY_INTERACTIVE"}}
        env.update(COLUMNS=str(COLUMNS), NO_COLOR="1", MPLBACKEND="Agg", PYTHONIOENCODING="utf-8",
                   PATH=f"{Path(sys.prefix) / 'bin'}{os.pathsep}{env.get('PATH', '')}")
        env.pop("LINES", None)
        t0 = time.perf_counter()
        proc = subprocess.run(["bash", "-c", command.text], cwd=self.root, env=env, stdin=subprocess.DEVNULL,
                              stdout=subprocess.PIPE, stderr=subprocess.STDOUT, timeout=COMMAND_TIMEOUT,
                              check=False)
        seconds = time.perf_counter() - t0
        output = proc.stdout.decode("utf-8", errors="replace").split("\n")
        return Result(proc.returncode, output, seconds)

    def remove(self) -> None:
        shutil.rmtree(self.root, ignore_errors=True)


def read_doc(doc: str) -> str:
    return (REPO / doc).read_text(encoding="utf-8")


def all_commands(docs: Sequence[str] = DOCS) -> list[Command]:
    return [c for doc in docs for c in parse_commands(doc, read_doc(doc))]


def describe_mismatch(command: Command, result: Result, workspace: Workspace) -> str:
    shown = normalise(command.shown or [])
    actual = normalise(result.output, workspace.names)
    diff = "\n".join(difflib.unified_diff(shown, actual, "shown in the document", "printed", lineterm=""))
    return (f"{command.ident}: the output shown differs from what `{command.key}` prints "
            f"(after the normalisations of tests/docs/doc_commands.py; '...' = one or more lines left out).\n"
            f"If the new output is right, regenerate the documents: .venv/bin/python tests/docs/update_docs.py\n"
            f"{diff}")


# Plots the documents show that their own commands draw: document -> {file the command writes: image shown}.
# The update mode copies each one over the image after running the document's commands.
IMAGES: dict[str, dict[str, str]] = {
    "docs/tutorial.md": {
        "fdfdd.png": "docs/img/planar_FDFDD.png",
        "sssss.png": "docs/img/planar_SSSSS.png",
        "sphere.png": "docs/img/sphere_FDFDF.png",
    },
}


def update_text(text: str, commands: Sequence[Command], results: dict[int, Result], workspace: Workspace) -> str:
    """``text`` with the shown output of each command in ``results`` (by line) rewritten from its result."""
    lines = text.split("\n")
    for c in sorted(commands, key=lambda c: c.out_start, reverse=True):
        if c.shown is None or c.line not in results:
            continue
        lines[c.out_start:c.out_end] = rewrite(c.shown, results[c.line].output, workspace.names)
    return "\n".join(lines)
