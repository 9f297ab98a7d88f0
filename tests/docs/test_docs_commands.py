"""The documents stay true: every command shown in README.md and docs/*.md runs and prints what is shown.

For each command of a shell block (the rules are in ``doc_commands.py``: ``$ `` sessions and command lists,
``...`` = one or more lines left out, and the only normalisations: trailing spaces, the temporary folder,
the sign of a printed zero, wall-clock times) one test runs it in a temporary copy of the
repository's ``examples/`` (the commands before it in the same document first, once per session, so
files it reads exist and the repository is never written to) and checks that it exits with status 0 and
that the output shown equals what it prints. A command is either run or listed in ``EXEMPT`` with the
reason, and ``test_every_command_is_run_or_exempt`` fails for one that is neither, so no new command is
skipped silently. The links and images of README.md and docs/*.md must resolve.

When an output changes on purpose, regenerate the documents in one command and read the diff:

    .venv/bin/python tests/docs/update_docs.py        # (--check: only say whether they are out of date)

A command that takes more than 30 s goes into ``SLOW`` (its case gets ``@pytest.mark.slow``).
"""

from __future__ import annotations

import re
from collections.abc import Iterator
from pathlib import Path

import pytest
from doc_commands import (
    DOCS,
    IMAGES,
    REPO,
    RUNNABLE,
    Command,
    Result,
    Workspace,
    _segments,
    all_commands,
    describe_mismatch,
    matches,
    normalise,
    parse_commands,
    read_doc,
    rewrite,
    strip_comment,
    update_text,
)

_SERVICE = "needs the running service (make run); the service's routes are tested in tests/api"

# Commands not run, by their first line (trailing comment removed), with the reason.
EXEMPT: dict[str, str] = {
    "make run": "serves the dashboard and API until stopped (tests/api covers the service)",
    "make test": "runs the whole suite, this test included",
    "make install": "installs into .venv, the environment this test runs in",
    ".venv/bin/python tests/docs/update_docs.py": "the update mode: rewrites the documents this test reads",
    ".venv/bin/python tests/docs/update_docs.py docs/tutorial.md": "the update mode for one document",
    "CTP_DATABASE_URL=postgresql+psycopg://ctp:ctp@127.0.0.1/ctp make run":
        "needs a PostgreSQL server and serves until stopped (tests/api runs the store on PostgreSQL in CI)",
    "curl -s localhost:8000/scenes/examples": _SERVICE,
    "curl -s -X POST localhost:8000/analyses -H 'content-type: application/json' \\": _SERVICE,
    "curl -s -X POST localhost:8000/plans -H 'content-type: application/json' \\": _SERVICE,
    "curl -s -X POST localhost:8000/scenes/contacts -H 'content-type: application/json' \\": _SERVICE,
    "curl -s localhost:8000/plans/<id>": _SERVICE,
    "curl -s localhost:8000/plans/<id>/result": _SERVICE,
}

# Commands (first line) that take more than 30 s, with the time measured; none at present.
SLOW: dict[str, str] = {}

COMMANDS = all_commands()


def first_line(command: Command) -> str:
    return command.key.split("\n")[0]


def exempt_reason(command: Command) -> str | None:
    return EXEMPT.get(first_line(command))


@pytest.fixture(scope="session")
def workspaces() -> Iterator[dict[str, Workspace]]:
    made: dict[str, Workspace] = {}
    yield made
    for ws in made.values():
        ws.remove()


def run_in_order(command: Command, workspaces: dict[str, Workspace]) -> tuple[Result, Workspace]:
    """Run ``command`` after the commands before it in its document (each at most once per session)."""
    if command.doc not in workspaces:
        workspaces[command.doc] = Workspace.create()
    ws = workspaces[command.doc]
    for c in COMMANDS:
        if c.doc != command.doc or exempt_reason(c) is not None or c.line in ws.results:
            continue
        ws.results[c.line] = ws.run(c)
        if c is command:
            break
    return ws.results[command.line], ws


def _case(command: Command) -> object:
    marks = [pytest.mark.slow] if first_line(command) in SLOW else []
    return pytest.param(command, id=command.ident, marks=marks)


@pytest.mark.parametrize("command", [_case(c) for c in COMMANDS])
def test_doc_command(command: Command, workspaces: dict[str, Workspace]) -> None:
    reason = exempt_reason(command)
    if reason is not None:
        pytest.skip(f"exempt, not run: {first_line(command)} ({reason})")
    result, ws = run_in_order(command, workspaces)
    tail = "\n".join(result.output[-30:])
    assert result.returncode == 0, (
        f"{command.ident}: `{command.key}` exited with status {result.returncode} "
        f"(a document showing a failure writes `CMD; echo \"exit code $?\"`):\n{tail}")
    if command.shown is not None:
        assert matches(command.shown, result.output, ws.names), describe_mismatch(command, result, ws)


def test_every_command_is_run_or_exempt() -> None:
    neither = [f"{c.ident}: {first_line(c)}" for c in COMMANDS
               if c.program not in RUNNABLE and exempt_reason(c) is None]
    assert not neither, (
        "commands in the documents that this test cannot run and that are not exempt; make them runnable, "
        "show them in a ```text block if they are not commands, or add their first line to EXEMPT in "
        "tests/docs/test_docs_commands.py with the reason:\n" + "\n".join(neither))


def test_exempt_and_slow_lists_name_commands_of_the_documents() -> None:
    firsts = {first_line(c) for c in COMMANDS}
    stale = sorted((set(EXEMPT) | set(SLOW)) - firsts)
    assert not stale, f"EXEMPT/SLOW entries that no document shows any more: {stale}"
    assert not set(SLOW) & set(EXEMPT)


def test_the_documents_hold_commands_that_are_checked() -> None:
    assert {"README.md", "docs/tutorial.md"} <= set(DOCS)
    for doc in ("README.md", "docs/tutorial.md"):
        shown = [c for c in COMMANDS if c.doc == doc and c.shown is not None and exempt_reason(c) is None]
        ran = [c for c in COMMANDS if c.doc == doc and exempt_reason(c) is None]
        assert ran, f"{doc}: no command is run"
        assert shown or doc == "README.md", f"{doc}: no command with its output shown"


def test_images_the_update_mode_refreshes_are_drawn_by_the_documents_commands() -> None:
    for doc, images in IMAGES.items():
        text = read_doc(doc)
        for produced, image in images.items():
            assert (REPO / image).is_file(), image
            assert Path(image).relative_to(Path(doc).parent).as_posix() in text, f"{doc} does not show {image}"
            writers = [c for c in COMMANDS if c.doc == doc and re.search(rf"--plot\s+{re.escape(produced)}\b", c.key)]
            assert writers, f"no command of {doc} writes {produced} (--plot)"


# ------------------------------------------------------------------------------------------- links and images

_CODE_SPAN = re.compile(r"`+[^`]*`+")
_LINK = re.compile(r"!?\[[^\]]*\]\(\s*<?([^)\s>]+)>?(?:\s+\"[^\"]*\")?\s*\)")
_REF = re.compile(r"^\s*\[[^\]]+\]:\s*(\S+)")
_IMG = re.compile(r"<img\s[^>]*src=\"([^\"]+)\"")


def prose_lines(text: str) -> Iterator[tuple[int, str]]:
    """Lines outside fenced blocks, with inline code removed."""
    fence: str | None = None
    for n, line in enumerate(text.split("\n"), 1):
        m = re.match(r"^\s*(`{3,}|~{3,})", line)
        if m:
            if fence is None:
                fence = m.group(1)
            elif line.strip().startswith(fence):
                fence = None
            continue
        if fence is None:
            yield n, _CODE_SPAN.sub("", line)


def github_anchors(text: str) -> set[str]:
    """The anchors GitHub gives the headings of a document."""
    anchors: set[str] = set()
    counts: dict[str, int] = {}
    for _, line in prose_lines(text.replace("`", "")):
        m = re.match(r"^#{1,6}\s+(.*?)\s*#*\s*$", line)
        if not m:
            continue
        slug = re.sub(r"[^\w\- ]", "", m.group(1).strip().lower()).replace(" ", "-")
        n = counts.get(slug, 0)
        counts[slug] = n + 1
        anchors.add(slug if n == 0 else f"{slug}-{n}")
    return anchors


def relative_links(text: str) -> Iterator[tuple[int, str]]:
    for n, line in prose_lines(text):
        for pattern in (_LINK, _REF, _IMG):
            for m in pattern.finditer(line):
                target = m.group(1)
                if not re.match(r"^[a-z][a-z0-9+.-]*:", target, re.I):  # http:, https:, mailto: ...
                    yield n, target


@pytest.mark.parametrize("doc", DOCS)
def test_relative_links_and_images_resolve(doc: str) -> None:
    base = (REPO / doc).parent
    broken = []
    for n, target in relative_links(read_doc(doc)):
        path, _, anchor = target.partition("#")
        file = (base / path).resolve() if path else REPO / doc
        if not file.exists():
            broken.append(f"{doc}:{n}: {target} (no file {file.relative_to(REPO) if REPO in file.parents else file})")
        elif anchor and file.suffix == ".md" and anchor not in github_anchors(file.read_text(encoding="utf-8")):
            broken.append(f"{doc}:{n}: {target} (no heading with anchor #{anchor})")
    assert not broken, "\n".join(broken)


# ------------------------------------------------------------------------------------------- the mechanism

SAMPLE = """Intro `make run`.

```
make run    # serves
.venv/bin/ctp plan a.json \\
    --goal active
```

```json
{"not": "a command"}
```

```
$ cat > x.json <<'EOF'
{"a": 1}
$ not a prompt inside the heredoc
EOF
$ .venv/bin/python -c "
print('two')  # a comment inside quotes
"
two

$ .venv/bin/ctp analyze x.json; echo "exit code $?"
head
...
tail
exit code 2
```
"""


def test_parse_reads_lists_sessions_heredocs_and_continuations() -> None:
    cs = parse_commands("sample.md", SAMPLE)
    assert [c.key.split("\n")[0] for c in cs] == [
        "make run", ".venv/bin/ctp plan a.json \\", "cat > x.json <<'EOF'", '.venv/bin/python -c "',
        '.venv/bin/ctp analyze x.json; echo "exit code $?"']
    assert [c.line for c in cs] == [4, 5, 14, 18, 23]
    assert cs[0].shown is None and cs[0].key == "make run" and cs[1].key.endswith("--goal active")
    assert cs[2].shown == [] and cs[2].text.endswith("EOF") and "not a prompt" in cs[2].text
    assert cs[3].shown == ["two"] and "# a comment inside quotes" in cs[3].key
    assert cs[4].shown == ["head", "...", "tail", "exit code 2"]
    assert strip_comment("a 'b # c' # d") == "a 'b # c'"


def test_matching_is_exact_but_for_the_ellipsis_and_the_normalisations() -> None:
    out = ["title", "row 1", "row 2", "row 3", "end"]
    assert matches(out, out)
    assert matches(["title", "...", "end"], out)
    assert matches(["title", "...", "row 2", "...", "end"], out)
    assert matches(["...", "row 3", "end"], out) and matches(["title", "row 1", "..."], out)
    assert not matches(["title", "row 1", "row 2", "row 3"], out)  # a line left out without '...'
    assert not matches(["title", "...", "row 1", "row 2", "row 3", "end"], out)  # '...' is one line or more
    assert not matches(["title", "...", "row 3", "row 2", "...", "end"], out)
    assert not matches(["title", "row 1", "row 2", "row 3", "end", "more"], out)
    assert not matches([], ["printed"]) and matches([], ["", "  "])
    assert not matches(["x = 0.010"], ["x = 0.012"]) and not matches(["[ 0.10]"], ["[-0.10]"])
    assert not matches(["x = 0.010 N"], ["x = 0.010 m"]) and not matches(["1e-3"], ["2e-3"])


def test_a_number_may_differ_by_one_unit_of_its_last_digit() -> None:
    """Normalisation 5: rounding on another CPU's BLAS moves a last digit by one, nothing more."""
    assert matches(["x = 0.010, 2.78 %"], ["x = 0.011, 2.79 %"])
    assert matches(["[ 0.339  1.000]"], ["[ 0.340  0.999]"])
    assert not matches(["[ 0.339  1.000]"], ["[ 0.341  1.000]"])
    assert not matches(["7 vertices"], ["8 vertices"]) and not matches(["step 3"], ["step 4"])  # counts: exact


def test_normalisations_are_the_documented_ones() -> None:
    assert normalise(["", "a  ", "[-0.00  0.50 -0.000 -0]", ""]) == ["a", "[ 0.00  0.50  0.000  0]"]
    assert normalise(["[-0.001 -0.0e+00 x-0.0]"]) == ["[-0.001 -0.0e+00 x-0.0]"]
    assert normalise(["8 nodes expanded in 2.51 s"]) == normalise(["8 nodes expanded in 13 s"])
    assert normalise(["moved in 1.16 s"]) != normalise(["moved in 1.17 s"])  # simulated time is compared
    assert normalise(["wrote /tmp/ws/a.json", "in /tmp/ws"], ["/tmp/ws"]) == ["wrote a.json", "in ."]


def test_rewrite_keeps_the_trimming_and_the_equal_lines() -> None:
    printed = ["title", "│ AAA │ yes │ [ 0.10] │", "│ BBB │ no  │ -       │", "│ CCC │ yes │ [ 0.30] │",
               "8 nodes expanded in 1.00 s", "end 2"]
    shown = ["title", "...", "│ CCC │ yes │ [ 0.20] │ sampled; │", "...", "8 nodes expanded in 9.99 s", "end 1"]
    new = rewrite(shown, printed)
    assert new == ["title", "...", "│ CCC │ yes │ [ 0.30] │", "8 nodes expanded in 9.99 s", "end 2"]
    assert matches(new, printed)
    assert rewrite(["old"], ["a", "b"]) == ["a", "b"] and rewrite([], ["a"]) == ["a"]
    assert rewrite(shown, printed[:1]) == ["title"]  # too short to trim: the whole output
    assert rewrite(["title", "...", "end 2"], printed) == ["title", "...", "end 2"]


def test_update_rewrites_only_the_output_blocks() -> None:
    cs = parse_commands("sample.md", SAMPLE)
    ws = Workspace(Path("/tmp/ws"))
    results = {cs[3].line: Result(0, ["one", "two", ""], 0.1),
               cs[4].line: Result(0, ["head", "x", "y", "tail", "exit code 2"], 0.1)}
    new = update_text(SAMPLE, cs, results, ws)
    assert new == SAMPLE.replace("\ntwo\n", "\none\ntwo\n")
    assert update_text(new, parse_commands("sample.md", new), results, ws) == new
    ok = {cs[4].line: Result(0, ["head", "tail", "exit code 2"], 0.1)}
    assert "...\n" not in update_text(SAMPLE, cs, ok, ws).split("$ .venv/bin/ctp analyze")[1]


def test_segments() -> None:
    assert _segments(["...", "a", "...", "b", "c"]) == ([["a"], ["b", "c"]], True, False)


def test_workspace_is_a_temporary_copy_of_the_examples_and_is_removed() -> None:
    ws = Workspace.create()
    try:
        assert REPO not in ws.root.parents and ws.root != REPO
        r = ws.run(Command("x.md", 1, 'pwd; echo "$COLUMNS"; ls examples/planar_disk_envelope.json; '
                                      "readlink -f .venv/bin/python > /dev/null && echo venv", []))
        assert r.returncode == 0
        assert normalise(r.output, ws.names) == [".", "120", "examples/planar_disk_envelope.json", "venv"]
    finally:
        ws.remove()
    assert not ws.root.exists()
