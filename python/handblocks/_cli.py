"""The ``handblocks`` console command a pip install puts on the venv's PATH.

The program itself (``launch``, ``replay``, ``echo`` ...; ``handblocks --help``) is the Rust
binary, with the renderer and every service in it: far too much to put in a wheel. This
command finds it and hands over (``exec``: its exit status, signals and terminal are the
program's own), looking in this order:

1. ``$HANDBLOCKS_BIN``, when set (any build of it, anywhere);
2. ``target/release/handblocks`` in the checkout this package was built from
   (``./run``, ``tests/run`` or ``cargo build --release`` leave it there);
3. another ``handblocks`` on ``PATH`` (``cargo install --path .`` puts one in ``~/.cargo/bin``).

When none is found it says so, with the command that builds one, and exits 2.
"""

from __future__ import annotations

import os
import shutil
import sys
from pathlib import Path
from typing import List, Optional, Sequence


def _is_program(path: Path) -> bool:
    return path.is_file() and os.access(path, os.X_OK)


def _this_command() -> Optional[Path]:
    try:
        return Path(sys.argv[0]).resolve()
    except (OSError, IndexError):
        return None


def candidates(env: Optional[dict] = None) -> List[Path]:
    """Where the program is looked for, in order (see the module's docs)."""
    env = os.environ if env is None else env
    found: List[Path] = []
    given = env.get("HANDBLOCKS_BIN")
    if given:
        found.append(Path(given))
        return found
    from . import _native

    if _native.BUILT_FROM:
        found.append(Path(_native.BUILT_FROM) / "target" / "release" / "handblocks")
    me = _this_command()
    path = env.get("PATH", "")
    for folder in path.split(os.pathsep):
        if not folder:
            continue
        p = Path(folder) / "handblocks"
        try:
            if me is not None and p.resolve() == me:
                continue  # this very command
        except OSError:
            continue
        found.append(p)
    return found


def find_program(env: Optional[dict] = None) -> Path:
    """The handblocks program this command runs; SystemExit(2) with what to do when none."""
    env = os.environ if env is None else env
    looked = candidates(env)
    for p in looked:
        if _is_program(p):
            return p
    if env.get("HANDBLOCKS_BIN"):
        why = f"HANDBLOCKS_BIN={env['HANDBLOCKS_BIN']} is not an executable file"
        todo = "set HANDBLOCKS_BIN to the handblocks program (target/release/handblocks in a checkout)"
    else:
        from . import _native

        why = "the handblocks program was not found (looked at: " + (
            ", ".join(str(p) for p in looked[:3]) or "nothing"
        ) + ("" if len(looked) <= 3 else ", ...") + ")"
        repo = _native.BUILT_FROM or "the handblocks checkout"
        todo = (
            f"build it: `cargo build --release --locked --bin handblocks` in {repo} (or run ./run "
            "there once), or set HANDBLOCKS_BIN to a handblocks program"
        )
    sys.stderr.write(f"handblocks (Python package): {why}; {todo}\n")
    raise SystemExit(2)


def main(argv: Optional[Sequence[str]] = None) -> None:
    """Runs the handblocks program with this command's arguments."""
    args = list(sys.argv[1:] if argv is None else argv)
    program = find_program()
    try:
        os.execv(str(program), [str(program), *args])
    except OSError as e:
        sys.stderr.write(f"handblocks (Python package): cannot run {program}: {e}\n")
        raise SystemExit(2)


if __name__ == "__main__":
    main()
