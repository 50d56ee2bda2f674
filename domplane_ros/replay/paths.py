"""Where a replay reads and writes: the paths checked before anything is written.

Nothing is written inside the input bag's folder; an existing output is replaced only with
``--force`` and only if it is a bag (``metadata.yaml`` and storage files), so that a mistyped
OUTPUT_BAG never deletes a folder of other files; an output that cannot be created (a
read-only or missing folder) refuses the run in one line. Every refusal is a
:class:`~domplane_ros.errors.BagError` (exit code 2, nothing written).
"""

from __future__ import annotations

from dataclasses import dataclass
import os
from pathlib import Path
from typing import Any, Callable

from domplane_ros.errors import BagError, clip_text
from domplane_ros.replay.reader import describe_error


@dataclass(frozen=True)
class RunPaths:
    """Where a run reads and writes, checked before anything is written."""

    input_bag: Path
    output_bag: Path
    csv: Path | None
    incomplete: Path          # where --keep-partial puts a partial bag
    csv_incomplete: Path | None

    @classmethod
    def check(cls, input_bag: str | os.PathLike[str], output_bag: str | os.PathLike[str],
              csv_path: str | os.PathLike[str] | None, force: bool,
              keep_partial: bool) -> RunPaths:
        """Return the paths, or raise BagError if the run must be refused."""
        input_path, output_path = Path(input_bag), Path(output_bag)
        csv_file = Path(csv_path) if csv_path is not None else None
        if not input_path.exists():
            raise BagError(f'input bag {str(input_path)!r} does not exist')
        check_paths(input_path, output_path, csv_file, force)
        paths = cls(input_path, output_path, csv_file,
                    output_path.with_name(output_path.name + '.incomplete'),
                    (csv_file.with_name(csv_file.name + '.incomplete')
                     if csv_file is not None else None))
        if keep_partial and not force:
            for path in (paths.incomplete, paths.csv_incomplete):
                if path is not None and (path.exists() or path.is_symlink()):
                    raise BagError(f'{str(path)!r} exists (where --keep-partial would put a '
                                   'partial output); use --force to replace it')
        if keep_partial:
            check_replaceable(paths.incomplete)
        return paths


def create_output(path: Path, what: str, make: Callable[[], Any]) -> Any:
    """Return ``make()``; an OSError (a read-only or missing folder) refuses the run.

    Raises:
        BagError: Naming ``path`` and the problem (nothing is written; exit code 2).

    """
    try:
        return make()
    except BagError:
        raise
    except OSError as err:
        problem = err.strerror or describe_error(err)
        failed = Path(str(err.filename)) if err.filename else None
        if failed is not None and '.partial' in failed.name:
            failed = failed.parent   # the hidden temporary file: name its folder instead
        where = f' ({str(failed)!r})' if failed is not None else ''
        raise BagError(f'cannot create the {what} {str(path)!r}: {problem}{where}') from err


def missing_folders(folder: Path) -> list[Path]:
    """Return ``folder`` and its ancestors that do not exist yet, deepest first."""
    missing = []
    folder = Path(os.path.abspath(folder))
    while not folder.exists() and folder != folder.parent:
        missing.append(folder)
        folder = folder.parent
    return missing


def remove_empty_folders(folders: list[Path]) -> None:
    """Remove the folders that are empty, deepest first (never raises)."""
    for folder in sorted(set(folders), key=lambda path: len(path.parts), reverse=True):
        try:
            folder.rmdir()
        except OSError:
            pass   # not empty (or gone): it holds something that is not ours to remove


def input_bag_folder(input_bag: Path) -> Path:
    """Return the folder an input bag occupies, resolved: nothing may be written inside it.

    A bag folder is itself; a storage file inside a bag folder (its folder holds
    ``metadata.yaml``, or the file is named after its folder as rosbag2 names them,
    ``NAME/NAME_0.db3``) is that folder; a storage file on its own is the file.
    """
    resolved = input_bag.resolve()
    if resolved.is_dir():
        return resolved
    folder = resolved.parent
    if (folder / 'metadata.yaml').exists() or resolved.name.startswith(folder.name + '_'):
        return folder
    return resolved


def check_paths(input_bag: Path, output_bag: Path, csv_path: Path | None,
                force: bool) -> None:
    """Refuse (BagError) an output or CSV file in the input bag, or one that exists."""
    in_res = input_bag_folder(input_bag)
    out_res = output_bag.resolve()
    if (out_res == in_res or in_res.is_relative_to(out_res) or out_res.is_relative_to(in_res)
            or input_bag.resolve().is_relative_to(out_res)):
        raise BagError(f'output {str(output_bag)!r} would overwrite or nest in the input bag '
                       f'{str(input_bag)!r} (its folder {str(in_res)!r})')
    if (output_bag.exists() or output_bag.is_symlink()) and not force:
        raise BagError(f'output {str(output_bag)!r} exists; use --force to replace it')
    check_replaceable(output_bag)
    if csv_path is not None:
        if (csv_path.resolve().is_relative_to(in_res) or csv_path.resolve() == out_res
                or csv_path.resolve().is_relative_to(out_res)):
            raise BagError(f'CSV file {str(csv_path)!r} would overwrite a bag')
        if csv_path.exists() and not force:
            raise BagError(f'CSV file {str(csv_path)!r} exists; use --force to replace it')
        if csv_path.is_dir():
            raise BagError(f'CSV file {str(csv_path)!r} is a directory')


# What a rosbag2 folder holds: --force replaces a folder of these files only.
_BAG_FILE_SUFFIXES = ('.db3', '.mcap', '.db3-shm', '.db3-wal', '.db3-journal')


def check_replaceable(path: Path) -> None:
    """Refuse (BagError) to replace anything at ``path`` but a bag, an empty folder or a link.

    ``--force`` replaces an earlier output; a folder that holds other files (a typo'd
    OUTPUT_BAG such as ``~/data``), or a regular file, would be deleted with it.
    """
    if path.is_symlink() or not path.exists():
        return   # replacing a link moves the link aside, not what it points to
    if not path.is_dir():
        raise BagError(f'output {str(path)!r} is a file, not a bag folder; --force only '
                       'replaces a bag (remove it yourself or choose another OUTPUT_BAG)')
    others = sorted(entry.name for entry in path.iterdir()
                    if not (entry.is_file() and (entry.name == 'metadata.yaml'
                                                 or entry.name.endswith(_BAG_FILE_SUFFIXES))))
    if others:
        listed = ', '.join(repr(clip_text(name, 60)) for name in others[:3])
        more = f' and {len(others) - 3} more' if len(others) > 3 else ''
        raise BagError(f'output {str(path)!r} is not a bag (it holds {listed}{more}); '
                       '--force only replaces a bag (metadata.yaml and .db3 or .mcap files): '
                       'remove it yourself or choose another OUTPUT_BAG')
