"""``femgrid-mpm plot``: pictures of a run's directory (PNGs, or an animation of its points).

Everything is read and checked first: a directory that is not a run, a damaged
file, a record out of range or options that do not go together are one line and
exit code 2, with nothing written.  Then each picture is written atomically.
"""

from __future__ import annotations

import argparse
import os
from pathlib import Path

from .parser import EXIT_DONE, EXIT_WRITE_FAILED, BadInput, emit, given_path, say

#: the default names of the pictures in the output directory
POINTS_PICTURE, ENERGY_PICTURE, ANIMATION = "points.png", "energy.png", "points"
#: the animation formats and their matplotlib writers
FORMATS = ("gif", "mp4")
#: frames per second of an animation without --fps
DEFAULT_FPS = 10
PICTURE_SUFFIXES = (".png", *(f".{kind}" for kind in FORMATS))


def record_number(text: str) -> int | str:
    """``--record N|last``: a record's number from 0, or ``last``."""
    if text == "last":
        return text
    try:
        value = int(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected a record number (0, 1, ...) or last, got {text!r}") from None
    if value < 0:
        raise argparse.ArgumentTypeError(f"expected a record number from 0 or last, got {value}")
    return value


def frames_per_second(text: str) -> int:
    """``--fps N``: a whole number from 1 to 60."""
    try:
        value = int(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected a whole number of frames per second, got {text!r}") from None
    if not 1 <= value <= 60:
        raise argparse.ArgumentTypeError(f"must be 1 to 60 (got {value})")
    return value


def add_arguments(command) -> None:
    """The arguments of ``femgrid-mpm plot``."""
    from ..plotting.run_directory import FIELDS

    command.add_argument("directory", type=given_path, metavar="DIR", help="the --out directory of femgrid-mpm run (finished, stopped or interrupted)")
    command.add_argument("--field", choices=list(FIELDS), default="velocity", metavar="NAME",
                         help=f"colour the points by this field (default: velocity, its magnitude): {', '.join(FIELDS)}")
    command.add_argument("--record", type=record_number, default="last", metavar="N|last",
                         help="the record of the particle series drawn (from 0; default: last)")
    command.add_argument("--only", choices=["points", "energy"], help="draw only this picture (default: both)")
    command.add_argument("--animate", action="store_true",
                         help="instead, animate every record of the particle series (particles.pvd)")
    command.add_argument("--format", choices=FORMATS, help="of the animation (default: gif, or the suffix of --out; "
                         "mp4 needs ffmpeg)")
    command.add_argument("--fps", type=frames_per_second, default=None, metavar="N",
                         help="frames per second of the animation (default: 10)")
    command.add_argument("--out", metavar="FILE_OR_DIR",
                         help="a directory for the pictures (created if missing; default: DIR), or one file "
                         "(.png with --only, .gif or .mp4 with --animate)")


def plot(args) -> int:
    """Draw the pictures of the run in ``args.directory``; see the module's docstring."""
    from ..plotting import RunUnreadable

    try:
        return _plot(args)
    except RunUnreadable as error:
        raise BadInput(str(error)) from None


def _plot(args) -> int:
    from ..plotting import RunDirectory, energy_figure, energy_table, points_figure, save, series_picture

    run = RunDirectory.open(args.directory)
    if args.animate:
        return _animate(args, run, series_picture)
    for option, value in (("--format", args.format), ("--fps", args.fps)):
        if value is not None:
            raise BadInput(f"{option}: is {'the format' if option == '--format' else 'the frame rate'} of an animation: "
                           "give it with --animate")
    wanted = [args.only] if args.only else ["points", "energy"]
    figures, notes = {}, []
    if "points" in wanted:
        if run.records:
            figures["points"] = points_figure(run, args.field, run.record_index(args.record))
        elif args.only:
            raise BadInput(f"{run.path}: has no points to draw yet (particles.pvd lists no records and there is no final.npz)")
        else:
            notes.append(f"no points drawn: {run.path} has no records of them yet")
    if "energy" in wanted:
        table = energy_table(run.energy) if run.energy is not None else None
        problem = ("no energy.csv (the scene's [output] energy = false, or the file was removed)" if table is None
                   else "energy.csv has no records yet" if len(table["time"]) == 0 else None)
        if problem is None:
            figures["energy"] = energy_figure(run, table)
        elif args.only:
            raise BadInput(f"{run.path}: {problem}")
        else:
            notes.append(f"no energy drawn: {problem}")
    if not figures:
        raise BadInput(f"{run.path}: has nothing to draw yet ({'; '.join(notes)})")
    names = {"points": POINTS_PICTURE, "energy": ENERGY_PICTURE}
    targets = _targets(args.out, run.path, {kind: names[kind] for kind in figures}, (".png",), "--only points|energy")
    for note in notes:
        say("note", note)
    for kind, figure in figures.items():
        if not _write(lambda: save(figure, targets[kind]), targets[kind]):
            return EXIT_WRITE_FAILED
        emit(f"wrote {targets[kind]}")
    return EXIT_DONE


def _animate(args, run, series_picture) -> int:
    from matplotlib.animation import FFMpegWriter, PillowWriter

    if args.only is not None:
        raise BadInput("--only: draws one picture; --animate draws the particle series (give one of them)")
    if not run.series:
        raise BadInput(f"--animate: {run.path} has no particle series (particles.pvd; the scene's "
                       "[output] particles = true writes it)")
    out = Path(args.out) if args.out else None
    suffix = out.suffix.lower() if out is not None and out.suffix.lower() in PICTURE_SUFFIXES else None
    kind = args.format or (suffix[1:] if suffix in (".gif", ".mp4") else "gif")
    if suffix is not None and suffix != f".{kind}":
        raise BadInput(f"--out {out}: an animation in {kind} is written to a .{kind} file (or give a directory)")
    if kind == "mp4" and not FFMpegWriter.isAvailable():
        raise BadInput("--format mp4: needs ffmpeg on the PATH, which is not there (install it, or use --format gif)")
    if len(run.records) == 0:
        raise BadInput(f"{run.path}: particles.pvd lists no records yet")
    if args.record != "last":
        raise BadInput("--record: draws one record; --animate draws all of them")
    picture = series_picture(run, args.field)  # reads and checks every record first
    target = _targets(args.out, run.path, {"animation": f"{ANIMATION}.{kind}"}, (f".{kind}",), "--animate")["animation"]
    fps = DEFAULT_FPS if args.fps is None else args.fps
    writer = PillowWriter(fps=fps) if kind == "gif" else FFMpegWriter(fps=fps)
    from ..plotting import write_animation

    if not _write(lambda: write_animation(picture, target, writer), target):
        return EXIT_WRITE_FAILED
    emit(f"wrote {target} ({len(run.records)} frames)")
    return EXIT_DONE


def _targets(out_text: str | None, default: Path, names: dict[str, str], suffixes: tuple[str, ...], single: str) -> dict[str, Path]:
    """Where each picture goes: into the directory ``--out`` (created, default: the run's),
    or, for one picture, the file ``--out`` (a name with a picture's suffix)."""
    if out_text is not None and not out_text:
        raise BadInput("--out: is empty (give a directory or a file)")
    out = Path(out_text) if out_text else default
    try:
        if out.suffix.lower() in PICTURE_SUFFIXES and not out.is_dir():
            if out.suffix.lower() not in suffixes:
                raise BadInput(f"--out {out}: this picture is a {' or '.join(suffixes)} file")
            if len(names) > 1:
                raise BadInput(f"--out {out}: is one file, and plot draws {len(names)} pictures "
                               f"(give a directory, or {single})")
            out.parent.mkdir(parents=True, exist_ok=True)
            return {kind: out for kind in names}
        if out.exists() and not out.is_dir():
            raise BadInput(f"--out {out}: exists and is not a directory")
        out.mkdir(parents=True, exist_ok=True)
        if not os.access(out, os.W_OK | os.X_OK):  # (a read-only mount too) before any picture is drawn
            raise BadInput(f"--out {out}: cannot write there (read-only)")
    except OSError as error:
        raise BadInput(f"--out {out}: cannot be used: {error.strerror or error}") from None
    targets = {kind: out / name for kind, name in names.items()}
    for target in targets.values():  # a directory in a picture's place: refused before any is written
        if target.is_dir() and not target.is_symlink():
            raise BadInput(f"{target}: is a directory, where a picture goes")
    return targets


def _write(write, target: Path) -> bool:
    """Run ``write``; False (and one line) if the file could not be written."""
    try:
        write()
    except OSError as error:
        say("error", f"cannot write {target}: {error.strerror or error}")
        return False
    return True
