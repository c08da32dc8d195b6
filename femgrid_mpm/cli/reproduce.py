"""``femgrid-mpm reproduce``: the paper's cases, every figure and table."""

from __future__ import annotations

import contextlib
import sys
import warnings

from .parser import EXIT_DONE, EXIT_INTERRUPTED, EXIT_WRITE_FAILED, BadInput, emit, output_directory, say
from .progress import runs_bar
from .signals import HANDLED, Interrupted


def reproduce(args) -> int:
    """Run the paper's cases (:data:`femgrid_mpm.reproduce.CASES`) into ``--out``."""
    from ..output import probe_writable
    from ..reproduce import CASES, PLANNED_RUNS
    from ..reproduce.timing import following

    unknown = [name for name in args.case if name not in CASES]
    if unknown:  # (with --list too: a misspelt case is not passed over)
        raise BadInput(f"--case {unknown[0]}: no such case (cases: {', '.join(CASES)})")
    if args.list:
        for name in CASES:
            emit(name)
        return EXIT_DONE
    out = output_directory(args.out)
    gallery = output_directory(args.gallery, "--gallery") if args.gallery is not None else None
    made = [place for place in (out, *out.parents) if not place.exists()]  # to take back if --gallery fails
    try:
        out.mkdir(parents=True, exist_ok=True)
        probe_writable(out)
    except OSError as error:
        raise BadInput(f"--out {out}: cannot write there: {error.strerror or error}") from None
    if gallery is not None:
        try:
            gallery.mkdir(parents=True, exist_ok=True)
            probe_writable(gallery)
        except OSError as error:
            for place in made:  # deepest first: exit 2 leaves nothing behind
                try:
                    place.rmdir()
                except OSError:
                    break
            raise BadInput(f"--gallery {gallery}: cannot write there: {error.strerror or error}") from None
    warnings.simplefilter("ignore")  # expected events (negative masses under "warn") are in the tables
    chosen = [name for name in CASES if not args.case or name in args.case]
    for name in chosen:  # before any case runs: each writes into its own directory
        if (out / name).exists() and not (out / name).is_dir():
            raise BadInput(f"--out {out}: {out / name} is a file, where case {name} writes its directory")
    bar, follow = runs_bar(sum(PLANNED_RUNS[name]() for name in chosen), sys.stderr.isatty())
    finished: list[str] = []
    try:
        with following(follow) if follow else contextlib.nullcontext():
            for name in chosen:
                if bar is None:
                    print(f"{name} ...", file=sys.stderr, flush=True)
                CASES[name](out / name)
                finished.append(name)
                table = out / name / "table.md"
                if table.exists():
                    (bar.write if bar is not None else emit)(table.read_text())
    except KeyboardInterrupt as interrupt:  # Ctrl-C, kill, a closed terminal (cli.signals)
        if bar is not None:
            bar.close()
        return interrupted(interrupt, out, chosen[len(finished)], finished)
    except OSError as error:  # a full disk while a case writes its figures or tables
        done = f"; the finished cases ({', '.join(finished)}) are in {out}" if finished else ""
        say("error", f"cannot write the outputs of case {chosen[len(finished)]} in {out / chosen[len(finished)]}: "
                     f"{error.strerror or error}{done}")
        return EXIT_WRITE_FAILED
    finally:
        if bar is not None:
            bar.close()
    if gallery is not None:
        from ..reproduce.gallery import copy_gallery

        try:
            copy_gallery(out, gallery, chosen)
        except OSError as error:  # after the run: its results are written, the copy is not
            say("error", f"--gallery {gallery}: cannot write there: {error.strerror or error}")
            return EXIT_WRITE_FAILED
    emit(f"reproduced {', '.join(chosen)}: figures and tables in {out}")
    return EXIT_DONE


def interrupted(interrupt: KeyboardInterrupt, out, case: str, finished: list[str]) -> int:
    """The line of a reproduction interrupted in ``case``, and its exit code (128 + the signal)."""
    signum = interrupt.signum if isinstance(interrupt, Interrupted) else None
    by = f" by {interrupt.name}" if signum is not None and HANDLED[signum] != EXIT_INTERRUPTED else ""
    kept = f"the finished cases ({', '.join(finished)}) are in {out}" if finished else "no case finished"
    say("interrupted", f"in case {case}{by}; {kept}")
    return HANDLED[signum] if signum is not None else EXIT_INTERRUPTED
