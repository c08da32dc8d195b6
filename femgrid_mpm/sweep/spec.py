"""A sweep file: a scene, the keys that vary and the keys set for every run.

::

    scene = "vibrating_bar"          # a bundled scene's name, or a path (relative to this file)
    particles = false                # write each run's particle series (default: none)
    [vary]                           # dotted keys of the scene, as with --set; the runs are the product
    "grid.basis" = ["q1", "q2"]
    "grid.spacing" = [0.5, 0.25]
    [[skip]]                         # combinations left out: each key's value (or one of its list)
    "grid.basis" = "q1"
    "grid.spacing" = 0.25
    [set]                            # dotted keys set in every run
    "time.end" = 1.0
    [report]
    error = "error_max"              # the error the report compares: error_max or error_end
    targets = [0.01, 0.001, 0.0001]  # the target errors the report answers for

:func:`plan` checks every combination (the scene loaded with its overrides)
before anything runs; a problem is a :class:`SweepError`, one line naming the
sweep file and the key.
"""

from __future__ import annotations

import collections
import hashlib
import itertools
import json
import math
import re
import warnings
from dataclasses import dataclass, field
from pathlib import Path
from typing import Annotated, Any, Literal

from pydantic import BaseModel, ConfigDict, Field, ValidationError

#: the keys of a run that name its place on the spacing and time-step axes of the report
SPACING_KEY = "grid.spacing"
TIME_STEP_KEYS = ("time.dt", "time.safety")
#: the sweep files shipped with the package
BUNDLED_SWEEPS = Path(__file__).parent.parent / "sweeps"
#: a run's directory name is at most this long (a longer one ends in a hash)
MAX_KEY_LENGTH = 80
#: the most runs a sweep plans unless its file raises ``max_runs``: planning loads and keeps
#: every combination's scene (about a millisecond each), so a product of long lists is
#: refused before any is loaded
DEFAULT_MAX_RUNS = 10_000

Scalar = str | int | float | bool


class SweepError(ValueError):
    """A sweep file that cannot be used; the message is one line naming the file and the key."""


class ReportSpec(BaseModel):
    """``[report]``: the error compared and the target errors answered for."""

    model_config = ConfigDict(extra="forbid", strict=True)
    error: Literal["error_max", "error_end"] = "error_max"
    targets: Annotated[list[Annotated[float, Field(gt=0, allow_inf_nan=False)]], Field(min_length=1)] = [1e-2, 1e-3, 1e-4]


class SweepSpec(BaseModel):
    """A sweep file's tables (see the module's docstring)."""

    model_config = ConfigDict(extra="forbid", strict=True)
    title: str = ""
    scene: Annotated[str, Field(min_length=1)]
    particles: bool = False
    max_runs: Annotated[int, Field(ge=1)] = DEFAULT_MAX_RUNS
    vary: dict[str, Annotated[list[Any], Field(min_length=1)]] = {}
    #: combinations left out of the product: one matches when each of the entry's keys has its value
    #: (or one of its list), e.g. a key that only one value of another key reads
    skip: list[Annotated[dict[str, Any], Field(min_length=1)]] = []
    set: dict[str, Any] = {}
    report: ReportSpec = ReportSpec()


@dataclass(frozen=True)
class PlannedRun:
    """One combination of a sweep: where it goes and what it runs.

    ``varied`` holds the values of the varied keys, ``overrides`` every dotted
    key set in the scene (``[set]``, then the varied ones), so that
    ``femgrid-mpm run SCENE --set KEY=VALUE ...`` with ``overrides`` is the same run.
    """

    key: str
    varied: dict
    overrides: dict
    scene_file: Path
    scene: Any = field(repr=False, compare=False)


def sweep_path(text: str) -> Path:
    """The sweep file ``text`` names: a path, or the name of a bundled sweep (``bar_convergence``)."""
    path = Path(text)
    bundled = BUNDLED_SWEEPS / f"{text}.toml"
    if not path.exists() and path.suffix != ".toml" and len(path.parts) == 1 and bundled.is_file():
        return bundled
    return path


def read_sweep(path) -> SweepSpec:
    """The sweep file at ``path``, checked; raises :class:`SweepError`.

    Only a regular file of at most :data:`~femgrid_mpm.reading.MAX_SCENE_BYTES` is read
    (a FIFO is refused without blocking), as a scene file is.  Two spellings of one key
    (``bodies.0.x`` and ``bodies.00.x``, in ``[vary]`` or across ``[vary]`` and ``[set]``),
    two values of a list that are one value (``2`` and ``2.0``) and more runs than
    ``max_runs`` are refused, the last before any combination is formed.
    """
    from ..reading import InputRefused, read_toml

    path = Path(path)
    try:
        data = read_toml(path, "sweep file")
    except InputRefused as error:
        raise SweepError(str(error)) from None
    try:
        spec = SweepSpec.model_validate(data)
    except ValidationError as error:
        raise SweepError(_one_line(f"{path}: {_describe(error)}")) from None
    runs = math.prod(len(values) for values in spec.vary.values())
    if runs > spec.max_runs:
        sizes = " x ".join(str(len(values)) for values in spec.vary.values())
        raise SweepError(f"{path}: vary: {runs} runs ({sizes}), more than max_runs = {spec.max_runs} "
                         "(raise it in the sweep file: max_runs = N)")
    spelled: dict[str, tuple] = {}
    for table, keys in (("vary", spec.vary), ("set", spec.set)):
        for key in keys:
            other = spelled.setdefault(normal_key(key), (table, key))
            if other != (table, key):
                same = "is also in [vary] (set a key in one of them)" if other[1] == key else \
                    f"is the key {_location(other)} spelled differently"
                raise SweepError(f"{path}: {_location((table, key))}: {same}")
    for key, values in spec.vary.items():
        seen: dict = {}
        for index, value in enumerate(values):
            if not isinstance(value, Scalar):
                raise SweepError(f"{path}: {_location(('vary', key, index))}: must be a string, a number or true/false "
                                 f"(got {type(value).__name__})")
            first = seen.setdefault(normal_value(value), index)
            if first != index:
                spelled_as = "" if _shown(values[first]) == _shown(value) else f" (as {_shown(values[first])})"
                raise SweepError(f"{path}: {_location(('vary', key, index))}: {_shown(value)} is already in the "
                                 f"list{spelled_as}")
    varied = {normal_key(key): {normal_value(v) for v in values} for key, values in spec.vary.items()}
    for index, entry in enumerate(spec.skip):
        for key, values in entry.items():
            if normal_key(key) not in varied:
                raise SweepError(f"{path}: skip[{index}]: {key!r} is not a key of [vary]")
            if values == []:  # matches no value: the entry would leave nothing out, unsaid
                raise SweepError(f"{path}: skip[{index}]: {key} = []: give the values to leave out")
            for value in values if isinstance(values, list) else [values]:
                if not isinstance(value, Scalar) or normal_value(value) not in varied[normal_key(key)]:
                    raise SweepError(f"{path}: skip[{index}]: {key} = {_shown(value)} is not one of its [vary] values")
    return spec


def skipped(spec: SweepSpec, varied: dict) -> bool:
    """Whether one combination of ``[vary]`` matches an entry of ``[[skip]]``."""
    values = {normal_key(key): normal_value(value) for key, value in varied.items()}
    return any(all(values[normal_key(key)] in {normal_value(v) for v in (wanted if isinstance(wanted, list) else [wanted])}
                   for key, wanted in entry.items()) for entry in spec.skip)


def normal_key(key: str) -> str:
    """A dotted key as the scene reads it: list indices as numbers (``bodies.00.x`` is ``bodies.0.x``)."""
    # ASCII digits only (int() refuses "²", which isdigit() takes), and no more than int() converts
    return ".".join(str(int(part)) if part.isascii() and part.isdigit() and len(part) < 4000 else part
                    for part in key.split("."))


def normal_value(value: Scalar) -> tuple:
    """What a varied value is to the scene: ``2`` and ``2.0`` are one number; ``true`` is no number."""
    if isinstance(value, bool):
        return ("bool", value)
    if isinstance(value, float) and value.is_integer():
        return ("number", int(value))
    if isinstance(value, (int, float)):
        return ("number", value)
    return ("text", value)


def scene_file(spec: SweepSpec, sweep_path) -> Path:
    """The scene file a sweep names: a bundled scene's name, or a path relative to the sweep file."""
    from ..scene import BUNDLED_SCENES

    name = spec.scene
    if name.endswith(".toml") or "/" in name or "\\" in name:
        path = Path(name)
        return path if path.is_absolute() else Path(sweep_path).parent / path
    bundled = BUNDLED_SCENES / f"{name}.toml"
    if not bundled.is_file():
        known = ", ".join(sorted(p.stem for p in BUNDLED_SCENES.glob("*.toml")))
        raise SweepError(f"{sweep_path}: scene: no bundled scene {name!r} (bundled: {known}; "
                         f"a file is named by its path, ending in .toml)")
    return bundled


def plan(spec: SweepSpec, sweep_path) -> list[PlannedRun]:
    """Every combination of ``spec``, each scene loaded with its overrides (checked), in
    the order of the file: the last key of ``[vary]`` changes fastest.

    Raises
    ------
    SweepError
        The first combination that does not load, naming the sweep file, the combination
        and the scene's key.
    """
    from ..scene import SceneError, load_scene

    from ..reading import read_regular_file

    path = scene_file(spec, sweep_path)
    try:  # the scene file's own problem (a FIFO, a directory), named before any override
        read_regular_file(path)
    except FileNotFoundError:
        raise SweepError(f"{sweep_path}: scene: no such scene file {str(path)!r}") from None
    except IsADirectoryError:
        raise SweepError(f"{sweep_path}: scene: {str(path)!r} is a directory, not a scene file") from None
    except OSError as error:
        raise SweepError(f"{sweep_path}: scene: {str(path)!r} cannot be read: {error.strerror or error}") from None
    path = path.absolute()
    try:
        base = load_scene(path, spec.set)
    except SceneError as error:
        raise SweepError(f"{sweep_path}: set: {error}") from None
    fixed = dict(spec.set)
    if base.output is not None and base.output.particles and not spec.particles:
        fixed["output.particles"] = False  # a sweep's runs write no particle series unless asked
    keys = list(spec.vary)
    combinations = [dict(zip(keys, values)) for values in itertools.product(*spec.vary.values())]
    combinations = [varied for varied in combinations if not skipped(spec, varied)]
    distinct = distinct_runs(combinations, base.solver.mass)
    if len(distinct) < len(combinations):
        from ..mass import OWN_KEYS

        merged = ", ".join(key for key in spec.vary if key.removeprefix("solver.") in OWN_KEYS)
        counted = f"{len(distinct)} distinct run{'s' if len(distinct) > 1 else ''}"
        warnings.warn(f"{sweep_path}: {len(combinations)} combinations, {counted}: the others differ from an earlier "
                      f"one only in keys their mass does not read ({merged}), and would run the same scene again",
                      MergedRunsWarning, stacklevel=2)
    combinations = distinct
    if not combinations:
        raise SweepError(f"{sweep_path}: skip: leaves no run")
    names = run_keys(combinations)
    runs = []
    for name, varied in zip(names, combinations):
        overrides = {**fixed, **varied}
        try:
            scene = load_scene(path, overrides)
        except SceneError as error:
            raise SweepError(f"{sweep_path}: vary: run {name}: {error}") from None
        runs.append(PlannedRun(name, varied, overrides, path, scene))
    return runs


class MergedRunsWarning(UserWarning):
    """Combinations of a sweep that would run the same scene as an earlier one (:func:`distinct_runs`)."""


def read_values(varied: dict, mass: str) -> tuple:
    """The keys and values of ``varied`` that a run of ``mass`` reads: all but the solver keys
    of another mass kind (:data:`femgrid_mpm.mass.OWN_KEYS`), the values as the scene reads them."""
    from ..mass import reads

    return tuple((key, normal_value(value)) for key, value in varied.items()
                 if not (key.startswith("solver.") and not reads(mass, key.removeprefix("solver."))))


def distinct_runs(combinations: list[dict], mass: str) -> list[dict]:
    """``combinations`` without those that differ from an earlier one only in solver keys
    their mass does not read (:data:`femgrid_mpm.mass.OWN_KEYS`; ``mass`` the scene's where
    ``solver.mass`` is not varied): they would run the same scene again.

    >>> distinct_runs([{"solver.mass": m, "solver.mix": a} for m in ("consistent", "lumped") for a in (0.0, 0.5)],
    ...               "lumped")
    [{'solver.mass': 'consistent', 'solver.mix': 0.0}, {'solver.mass': 'consistent', 'solver.mix': 0.5}, \
{'solver.mass': 'lumped', 'solver.mix': 0.0}]
    """
    seen, kept = set(), []
    for varied in combinations:
        read = read_values(varied, varied.get("solver.mass", mass))
        if read not in seen:
            seen.add(read)
            kept.append(varied)
    return kept


def run_keys(combinations: list[dict]) -> list[str]:
    """Directory names of the runs: the varied values, slugified and joined by ``-``
    (``q2-consistent-0.25``); a name that would be too long or is taken twice ends in a
    hash of its values instead.

    >>> run_keys([{"grid.basis": "q2", "grid.spacing": 0.25}, {"grid.basis": "Q2", "grid.spacing": 0.25},
    ...           {"grid.basis": "q1", "grid.spacing": 0.25}])
    ['q2-0.25-edf429a7', 'q2-0.25-dd1ec223', 'q1-0.25']
    >>> run_keys([{}])
    ['run']
    """
    slugs = ["-".join(_slug(value) for value in varied.values()) or "run" for varied in combinations]
    taken = collections.Counter(slugs)
    names = []
    for slug, varied in zip(slugs, combinations):
        if len(slug) > MAX_KEY_LENGTH or taken[slug] > 1:
            digest = hashlib.sha256(json.dumps(varied, sort_keys=True).encode()).hexdigest()[:8]
            slug = f"{slug[: MAX_KEY_LENGTH - 9]}-{digest}"
        names.append(slug)
    return names


def _slug(value: Scalar) -> str:
    if isinstance(value, bool):
        text = "true" if value else "false"
    elif isinstance(value, float):
        text = repr(value)
    else:
        text = str(value)
    return re.sub(r"[^a-z0-9.+]", "_", text.lower()).strip(".") or "_"


def _shown(value) -> str:
    return json.dumps(value) if isinstance(value, str) else (str(value).lower() if isinstance(value, bool) else repr(value))


def _describe(error: ValidationError) -> str:
    """The first problem of a sweep file, as ``key: message``."""
    first = error.errors(include_url=False)[0]
    location = _location(first["loc"])
    kind = first["type"]
    if kind == "extra_forbidden":
        known = {(): SweepSpec, ("report",): ReportSpec}.get(tuple(first["loc"][:-1]))
        fields = f" (keys: {', '.join(known.model_fields)})" if known is not None else ""
        return f"{location}: unknown key{fields}"
    if kind == "missing":
        return f"{location}: is required"
    if kind == "too_short":
        return f"{location}: must not be empty"
    message = first["msg"]
    if "input" in first and isinstance(first["input"], (str, int, float, bool)):
        message += f" (got {_shown(first['input'])})"
    return f"{location}: {message}"


def _location(parts) -> str:
    """``vary."grid.basis"[0]``: a location in the file, dotted keys quoted as in TOML."""
    text = ""
    for part in parts:
        if isinstance(part, int):
            text += f"[{part}]"
        else:
            part = json.dumps(part) if "." in part else part
            text += f".{part}" if text else part
    return text


def _one_line(text: str) -> str:
    return " ".join(text.split())
