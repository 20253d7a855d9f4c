"""Planning a campaign: which recordings, what kind each is, and the tasks they divide into.

A task is a block of consecutive sets of one recording, described by plain values (a path and
positions), so it pickles to a worker that opens the file itself. A recording is one task unless
it is large: the station's processor carries state from set to set (the temporal unwrapper's
reference phase, the aperture being confirmed, the carrier), so a block may only start where that
state is reset anyway, at a set that adopted a new aperture (``/apertures/from_set``). A block
then starts from a fresh processor exactly as the continuing run would; each block but the last
also processes the next block's first set, to check that the continuing run did adopt there (with
other settings the adoptions may differ); when it did not, the recording is run again as one task
(:func:`whole_recording`).
"""

from __future__ import annotations

import hashlib
import json
from collections.abc import Sequence
from dataclasses import dataclass, replace
from pathlib import Path
from typing import Final, Literal

import h5py
import numpy as np

from wavestack import __version__
from wavestack.loop import MAP_KIND, read_campaign
from wavestack.pipeline import InputError
from wavestack.pipeline.formats import check_allocation
from wavestack.recording import FORMAT_NAME, RecordingReader
from wavestack.pipeline.formats.hdf5_open import open_hdf5_readonly

#: A block of a large recording holds at least this many sets: ~10 ms per set on the small
#: station, so a task is ~0.5 s or more, against ~1 ms of scheduling per task.
MIN_BLOCK_SETS: Final = 48
#: Version of what a result row holds: part of the settings hash, so a change re-analyses.
RESULTS_VERSION: Final = 1
POLISH_FORMAT: Final = "wavestack-polish-campaign"
ALIGN_FORMAT: Final = "wavestack-align"

Kind = Literal["station", "polish", "unsupported", "unreadable"]


@dataclass(frozen=True)
class Task:
    """One unit of work: sets ``start`` .. ``stop - 1`` of one recording.

    Attributes
    ----------
    path : str
        The recording (every worker must see it under this path).
    key : str
        The recording's key in the results: file hash and settings hash.
    kind : {"station", "polish", "unsupported", "unreadable"}
    start, stop : int
        Positions of the first and one past the last set (or map) of the block.
    check_next : bool
        Also process the set at ``stop`` to check that the continuing run adopts an aperture there.
    config_text : str or None
        The station configuration to process with (TOML), None for the recorded one.
    message : str
        Why a recording is unsupported or unreadable (empty otherwise).
    """

    path: str
    key: str
    kind: Kind
    start: int
    stop: int
    check_next: bool = False
    config_text: str | None = None
    message: str = ""

    @property
    def sets(self) -> int:
        return self.stop - self.start


@dataclass(frozen=True)
class RecordingPlan:
    """One recording of the campaign and its tasks.

    Attributes
    ----------
    path : str
    file_sha256 : str
        SHA-256 of the file's bytes (hex).
    settings_hash : str
    kind : str
    sets : int
        Sets (station) or maps (polish) the recording holds.
    tasks : tuple of Task
    """

    path: str
    file_sha256: str
    settings_hash: str
    kind: Kind
    sets: int
    tasks: tuple[Task, ...]

    @property
    def key(self) -> str:
        return f"{self.file_sha256[:16]}-{self.settings_hash[:16]}"


def settings_hash(config_text: str | None) -> str:
    """SHA-256 (hex) of the settings a campaign runs with: the configuration (None: each
    recording's own), the software version and the result layout version.

    Examples
    --------
    >>> settings_hash(None) == settings_hash(None) != settings_hash("[processing]")
    True
    """
    settings: dict[str, object] = {"config": config_text, "software": __version__, "results": RESULTS_VERSION}
    text = json.dumps(settings, sort_keys=True)
    return hashlib.sha256(text.encode("utf-8")).hexdigest()


def file_sha256(path: str | Path) -> str:
    """SHA-256 (hex) of a file's bytes; raises InputError when it cannot be read."""
    try:
        with open(path, "rb") as stream:
            return hashlib.file_digest(stream, "sha256").hexdigest()
    except OSError as error:
        raise InputError(f"{path}: cannot read it ({error.strerror or error})") from error


def plan_recording(path: str, config_text: str | None, *, min_block_sets: int = MIN_BLOCK_SETS) -> RecordingPlan:
    """Identify one recording and divide it into tasks (see the module notes).

    A file that is not a recording wavestack can re-analyse is planned too, as one task of kind
    ``unsupported`` or ``unreadable`` with the reason, so that it is reported in the results.

    Raises
    ------
    InputError
        The file cannot be read at all (missing, a directory, no permission).
    """
    digest = file_sha256(path)
    settings = settings_hash(config_text)
    key = f"{digest[:16]}-{settings[:16]}"
    kind, sets, starts, message = _inspect(path)
    if kind != "station" or sets < 2 * min_block_sets:
        tasks = (Task(path, key, kind, 0, sets, False, config_text, message),)
    else:
        bounds = _block_bounds(sets, starts, min_block_sets)
        tasks = tuple(Task(path, key, kind, a, b, b < sets, config_text, "")
                      for a, b in zip(bounds, bounds[1:]))
    return RecordingPlan(path, digest, settings, kind, sets, tasks)


def whole_recording(plan: RecordingPlan) -> Task:
    """The recording as one task (when a block boundary did not hold)."""
    return replace(plan.tasks[0], start=0, stop=plan.sets, check_next=False)


def _block_bounds(sets: int, starts: Sequence[int], min_sets: int) -> list[int]:
    """0, the aperture starts kept as block boundaries (each block >= ``min_sets``), ``sets``."""
    bounds = [0]
    for start in starts:
        if start - bounds[-1] >= min_sets and sets - start >= min_sets:
            bounds.append(start)
    return [*bounds, sets]


def _inspect(path: str) -> tuple[Kind, int, list[int], str]:
    """(kind, sets or maps, positions where an aperture was adopted, message).

    A file that cannot be analysed is planned as ``unreadable`` with the reason naming it, whatever
    went wrong in reading it: one bad file fails its own task, never the campaign's planning.
    """
    try:
        return _identify(path)
    except InputError as error:
        return "unreadable", 0, [], str(error)
    except Exception as error:  # noqa: BLE001 - a reader's bug on a hostile file: that file only, named
        return "unreadable", 0, [], f"{path}: cannot be read ({type(error).__name__}: {error})"


def _identify(path: str) -> tuple[Kind, int, list[int], str]:
    opened = open_hdf5_readonly(Path(path))  # not HDF5, a damaged superblock: InputError
    try:
        attrs = opened.file.attrs
        found = attrs.get("format")
        found = found.decode("utf-8", "replace") if isinstance(found, bytes) else found
        if found == ALIGN_FORMAT:
            return "unsupported", 0, [], (f"{path}: an alignment record (wavestack align) holds fitted terms and "
                                          "hexapod moves, not frames or maps; not a station recording, nothing "
                                          "to re-analyse")
        if found != FORMAT_NAME and found != POLISH_FORMAT:
            return "unsupported", 0, [], (f"{path}: not a station recording (format {found!r}; expected "
                                          f"{FORMAT_NAME!r} from wavestack run --record)")
    finally:
        opened.file.close()
    if found == POLISH_FORMAT:
        return "polish", _polish_maps(path), [], ""
    with RecordingReader(path) as reader:  # refuses what the file declares but does not hold, before allocating
        return "station", reader.n_sets, _adoption_positions(reader.set_indices, reader.aperture_sets), ""


def _polish_maps(path: str) -> int:
    """The surface maps of a polish campaign record (the loop kernel's map records), checked to be what
    the task may read: one block, read and stacked.

    Raises
    ------
    InputError
        An unreadable record, no intact first map with its aperture, maps whose shapes disagree with
        the aperture, or maps beyond the memory budget.
    """
    log = read_campaign(Path(path), POLISH_FORMAT)  # each array's allocation is checked before it is read
    maps = log.of_kind(MAP_KIND)
    if not maps or "aperture_mask" not in maps[0].arrays:
        raise InputError(f"{path}: polish campaign record without an intact first surface map")
    mask_shape = maps[0].arrays["aperture_mask"].shape
    shapes = {tuple(m.arrays["map"].shape) if "map" in m.arrays else None for m in maps}
    if len(mask_shape) != 2 or shapes != {mask_shape}:
        raise InputError(f"{path}: polish campaign record: surface maps {sorted(map(str, shapes))}, aperture "
                         f"{mask_shape}; expected every map (H, W) as the aperture")
    check_allocation(path, "surface maps", (2 * len(maps), *mask_shape), 8)  # read and stacked
    return len(maps)


def _adoption_positions(set_indices: np.ndarray, from_sets: np.ndarray) -> list[int]:
    """Positions of the sets at which the live run adopted an aperture."""
    wanted = set(int(s) for s in from_sets)
    return [p for p, s in enumerate(set_indices.tolist()) if s in wanted]
