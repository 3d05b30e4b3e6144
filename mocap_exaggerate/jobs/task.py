"""One clip of a batch as a task: `convert_file`, what every executor runs (and a farm task may call).

It never raises for a bad file: whatever goes wrong is the result's one-line
``error``, so the rest of the batch goes on. `clear_temporaries` removes what a
task's process left when it died mid-write (killed, out of memory), which
nothing in the process itself could.
"""

from __future__ import annotations

import os
import time
from pathlib import Path

from ..core.errors import MocapError
from ..io.files import OutputExistsError
from .batch_types import BatchOptions, Clip, FileResult
from .resume import kept_result, resume_check

__all__ = ["convert_file", "clear_temporaries"]


def convert_file(clip: Clip, out_dir: str | os.PathLike, options: BatchOptions,
                 parameters: str | None = None, label: str | None = None) -> FileResult:
    """Convert one clip of a batch into ``out_dir/<its folder>/``; never raises for a bad file.

    Whatever goes wrong (a malformed or unreadable file, outputs that exist, a
    full disk, a bug) is the returned result's ``error``, in one line.
    label : how the manifest and the result name the input (default: ``clip.source``)
    """
    from .job import convert

    started = time.perf_counter()
    label = label if label is not None else str(clip.source)

    def failed(message: str) -> FileResult:
        return FileResult(label, "failed", seconds=time.perf_counter() - started, error=message)

    redo = None
    try:
        if options.resume:
            redo, kept = resume_check(clip, out_dir, options, parameters)
            if redo is None:
                return kept_result(label, clip, out_dir, started, kept)
        record = convert(clip.source, Path(out_dir) / clip.relative.parent, options.config, preset=options.preset,
                         name=clip.name, label=label, overwrite=options.overwrite or options.resume,
                         parameters=parameters, protect=options.protect)
    except OutputExistsError as error:
        return failed(f"{error}; --overwrite replaces it (batch --resume keeps finished clips, redoes the rest)")
    except MocapError as error:
        return failed(str(error))
    except OSError as error:
        where = f"{error.filename}: " if getattr(error, "filename", None) else ""
        return failed(f"{where}{error.strerror or error}")
    except MemoryError:
        return failed("out of memory")
    except Exception as error:  # a bug: reported with the file, and the rest go on
        return failed(f"internal error, please report it: {type(error).__name__}: {error}")
    notes = ([f"redone: {redo}"] if redo and redo != "no outputs yet" else []) + list(record.notes)
    if options.report:
        from ..viz.report import write_pictures

        warnings = list(record.warnings)
        try:  # the outputs are written and sound: a picture that cannot be drawn is a warning, not a failure
            write_pictures(record, out_dir, options.config)
        except OSError as error:
            where = f"{error.filename}: " if getattr(error, "filename", None) else ""
            warnings.append(f"no report pictures: {where}{error.strerror or error}")
        except Exception as error:
            warnings.append(f"no report pictures: {type(error).__name__}: {error}")
        record.warnings = warnings
    return FileResult(label, "converted", outputs={kind: str(path) for kind, path in record.outputs.items()},
                      frames=record.frames, seconds=time.perf_counter() - started,
                      max_link_stretch=round(record.max_link_stretch, 6), warnings=list(record.warnings),
                      notes=notes)


def clear_temporaries(clip: Clip, out_dir: str | os.PathLike, options: BatchOptions) -> list[Path]:
    """Delete the temporary files a conversion of ``clip`` left under ``out_dir`` when its process
    died mid-write (its outputs and, with a report, its pictures); the ones removed.

    The outputs already in place are left alone: their manifest vouches for them or for none.
    """
    from ..io.files import remove_stale_temporaries
    from .job import output_paths

    folder = Path(out_dir) / clip.relative.parent
    from ..config import USD_FORMATS

    targets = list(output_paths(folder, clip.name, fbx=True).values())
    targets += [folder / f"{clip.name}.{suffix}" for suffix in USD_FORMATS]  # whichever a run wrote
    if options.report:
        from ..viz.report import picture_paths

        targets += picture_paths(out_dir, folder / f"{clip.name}.json").values()
    removed = []
    for target in targets:
        try:
            removed += remove_stale_temporaries(target)
        except OSError:  # what cannot be removed now, the clip's next conversion removes
            pass
    return removed
