"""What a batch works on and what it says back: `Clip`, `BatchOptions`, `FileResult`, `BatchInterrupted`.

Plain data, imported by every part of a batch (`discovery`, `resume`, `task`,
the executors) and pickled to its workers.
"""

from __future__ import annotations

import json
from dataclasses import asdict, dataclass, field
from pathlib import Path

from ..config import PipelineConfig

__all__ = ["Clip", "BatchOptions", "FileResult", "BatchInterrupted"]


@dataclass(frozen=True)
class Clip:
    """One input of a batch.

    source : the file
    relative : where it sits under the input folder; its outputs sit at the same
        place under the output folder (``walk/a.bvh`` -> ``OUT/walk/a.bvh``, ``.glb``, ...)
    """

    source: Path
    relative: Path

    @property
    def name(self) -> str:
        return self.relative.stem


@dataclass(frozen=True)
class BatchOptions:
    """What every clip of a batch is converted with (`convert`'s options).

    config : the pipeline, its ``[glb]`` block included (whether the GLB is written, its units
        and influences, the character and its joint map): the one place they are said. Give
        file paths that every worker can read (absolute ones, for a Dask cluster)
    preset : the shipped preset it was resolved from, recorded in each manifest
    resume : keep the clips whose output set is complete and was made from the same
        input bytes with the same parameters; redo the rest (replacing what they left)
    overwrite : replace existing outputs; without it (or resume) a clip whose outputs
        exist fails, saying so
    report : also draw each clip's pictures for the batch's report (`mocap_exaggerate.viz.report`)
    protect : more files no clip's outputs may land on (the pipeline file the config was read from);
        absolute paths, as the skin's
    """

    config: PipelineConfig
    preset: str | None = None
    overwrite: bool = False
    resume: bool = False
    report: bool = False
    protect: tuple[str, ...] = ()


@dataclass
class FileResult:
    """What happened to one file: ``converted``, ``skipped`` or ``failed`` (with ``error``).

    warnings : what the reader noticed in the input (extra lines, a frame rate overridden)
    notes : what the pipeline did worth hearing (rest frames, strikes found), and why
        ``resume`` redid the clip
    """

    input: str
    status: str
    outputs: dict[str, str] = field(default_factory=dict)
    frames: int | None = None
    seconds: float = 0.0
    max_link_stretch: float | None = None
    error: str | None = None
    warnings: list[str] = field(default_factory=list)
    notes: list[str] = field(default_factory=list)

    def to_json(self) -> str:
        """One line of JSON (``batch --json``)."""
        return json.dumps({**asdict(self), "seconds": round(self.seconds, 4)})


class BatchInterrupted(Exception):
    """A batch stopped before its end: the files that finished (``results``) and those not done (``pending``).

    reason : None after Ctrl-C; what stopped it otherwise (the Dask scheduler was lost)
    """

    def __init__(self, results: list[FileResult], pending: list[Clip], reason: str | None = None) -> None:
        super().__init__(reason or f"interrupted: {len(results)} file(s) finished, {len(pending)} not started")
        self.results = results
        self.pending = pending
        self.reason = reason
