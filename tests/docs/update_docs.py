"""Update mode of the docs test: run every command of README.md and docs/*.md and rewrite the outputs shown.

    .venv/bin/python tests/docs/update_docs.py            # rewrite README.md and docs/*.md (the tutorial)
    .venv/bin/python tests/docs/update_docs.py docs/tutorial.md   # one document
    .venv/bin/python tests/docs/update_docs.py --check    # change nothing; exit 1 if a document is out of date

Each document's commands run in order in a fresh temporary folder (as the test runs them, see
``doc_commands.py``); the output block after each ``$ `` command is replaced by what the command printed,
trimmed where the document trims it (``...``), and the plots listed in ``doc_commands.IMAGES`` are copied
over the images the document shows. The commands ``EXEMPT`` in ``test_docs_commands.py`` are not run. A
command that exits with a status other than 0 leaves its block alone and makes the script exit 1. Read the
diff (``git diff README.md docs/``) before committing: the prose around an output may need the same change.
"""

from __future__ import annotations

import argparse
import shutil
import sys
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))

from doc_commands import DOCS, IMAGES, REPO, Result, Workspace, parse_commands, read_doc, update_text
from test_docs_commands import EXEMPT, exempt_reason


def update(doc: str, check: bool) -> tuple[bool, bool]:
    """Rewrite one document; (whether it changed or would change, whether every command succeeded)."""
    text = read_doc(doc)
    commands = parse_commands(doc, text)
    workspace = Workspace.create()
    results: dict[int, Result] = {}
    ok = True
    try:
        for c in commands:
            reason = exempt_reason(c)
            if reason is not None:
                print(f"  skip {c.ident}: {c.key.splitlines()[0]}  ({reason})")
                continue
            r = workspace.run(c)
            print(f"  ran  {c.ident} in {r.seconds:.1f} s: {c.key.splitlines()[0]}")
            if r.returncode != 0:
                ok = False
                tail = "\n".join(r.output[-15:])
                print(f"  FAILED with exit status {r.returncode}; its output is left as it is:\n{tail}")
                continue
            results[c.line] = r
        new = update_text(text, commands, results, workspace)
        changed = new != text
        if changed and not check:
            (REPO / doc).write_text(new, encoding="utf-8")
        for produced, image in IMAGES.get(doc, {}).items():
            source = workspace.root / produced
            if not source.exists():
                ok = False
                print(f"  no {produced} was written: {image} not updated")
            elif not check:
                shutil.copyfile(source, REPO / image)
        print(f"{doc}: {'out of date' if check and changed else 'rewritten' if changed else 'up to date'}")
        return changed, ok
    finally:
        workspace.remove()


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("docs", nargs="*", default=list(DOCS), help="documents (default: %(default)s)")
    parser.add_argument("--check", action="store_true", help="write nothing; exit 1 if a document would change")
    args = parser.parse_args(argv)
    unknown = [d for d in args.docs if d not in DOCS]
    if unknown:
        parser.error(f"not a checked document: {', '.join(unknown)} (choose from {', '.join(DOCS)})")
    assert EXEMPT  # the list the test checks is the one used here
    any_changed, all_ok = False, True
    for doc in args.docs:
        changed, ok = update(doc, args.check)
        any_changed |= changed
        all_ok &= ok
    return 1 if not all_ok or (args.check and any_changed) else 0


if __name__ == "__main__":
    sys.exit(main())
