"""Output folders that are never overwritten by accident and never left half-written.

Every command that writes a folder follows two rules (docs/reference/reliability.md, section 2):

* :func:`check_output_dir`, called before any work starts, refuses an existing non-empty folder unless the user
  said ``--force``, a path that is a file, and a place where the folder cannot be created; and, with or without
  ``--force``, the working folder, an input of the command, a folder inside an input and a folder that contains one
  (replacing it would delete what the user gave);
* :func:`atomic_output_dir` yields a fresh temporary folder beside the target (same parent, so the final
  ``rename`` is atomic on one file system), and moves it into place only when the ``with`` block ends normally.
  On any exception, Ctrl-C included, the temporary folder is removed and the target is exactly as it was.

>>> import tempfile, pathlib
>>> target = pathlib.Path(tempfile.mkdtemp()) / "run"
>>> with atomic_output_dir(target) as tmp:
...     _ = (tmp / "result.txt").write_text("42")
>>> (target / "result.txt").read_text()
'42'
>>> check_output_dir(target)  # doctest: +ELLIPSIS
Traceback (most recent call last):
...
evio_lib.io.output_dir.OutputExistsError: output folder ... already exists and is not empty; use --force to replace it
"""
from __future__ import annotations

import os
import secrets
import shutil
import tempfile
from contextlib import contextmanager
from pathlib import Path
from typing import Iterable, Iterator

__all__ = ["OutputExistsError", "check_output_dir", "check_inputs_apart", "atomic_output_dir"]


class OutputExistsError(ValueError):
    """The output folder already holds files and the user did not ask to replace them (``--force``)."""


def _nearest_existing(path: Path) -> Path:
    """Return ``path`` or its nearest ancestor that exists."""
    path = Path(os.path.abspath(path))
    while not path.exists() and path != path.parent:
        path = path.parent
    return path


def _real(path: str | Path) -> str:
    """Return the absolute path of ``path`` with every symbolic link resolved (the path need not exist)."""
    return os.path.realpath(os.path.abspath(path))


def _within(inner: str, outer: str) -> bool:
    """Return whether the resolved path ``inner`` is ``outer`` or lies below it."""
    return inner == outer or inner.startswith(outer.rstrip(os.sep) + os.sep)


#: The installed library (its code and shipped weights): never an output folder nor inside one.
_PACKAGE_DIR = Path(__file__).resolve().parents[1]
#: How deep below an input folder its symbolic links are looked for (EuRoC's mav0/cam0/data is 3 deep), and how many
#: entries at most are looked at (a recording's frames folder can hold tens of thousands).
_LINK_DEPTH, _LINK_ENTRIES = 3, 20000


def _spellings(path: str | Path) -> list[str]:
    """Return the absolute path as given (links kept) and resolved (links followed): both name the same place."""
    literal = os.path.normpath(os.path.abspath(path))
    real = _real(path)
    return [literal] if literal == real else [literal, real]


def _link_targets(folder: str | Path) -> list[tuple[str, str]]:
    """Return (link, resolved target) of the symbolic links inside ``folder`` (depth <= _LINK_DEPTH).

    A recording whose files or sub-folders are links (frames kept elsewhere, a shared ground truth) reads those
    targets: they are inputs as much as the folder.
    """
    found: list[tuple[str, str]] = []
    if not os.path.isdir(folder):
        return found
    top = os.path.normpath(os.path.abspath(folder))
    seen = 0
    for root, dirs, files in os.walk(top, followlinks=False):
        depth = root[len(top):].count(os.sep)
        for entry in dirs + files:
            seen += 1
            full = os.path.join(root, entry)
            if os.path.islink(full):
                found.append((full, _real(full)))
        if depth + 1 >= _LINK_DEPTH or seen > _LINK_ENTRIES:
            dirs[:] = []
    return found


def check_inputs_apart(path: str | Path, inputs: Iterable[tuple[str, str | Path | None]] = (),
                       name: str = "output folder") -> None:
    """Raise ValueError when the output folder ``path`` would overlap the working folder or one of ``inputs``.

    Refused, with or without ``--force`` (replacing such a folder would delete what the command reads, or the user's
    working folder): the working folder itself and any folder that contains it; a folder that is an input, lies
    inside an input or contains one; the ``evio_lib`` package, a folder that contains it, and an existing folder
    inside it (its code and shipped weights). Paths are compared as given and with their symbolic links resolved
    (``os.path.realpath``): a link to the input is the input, a link inside the input lies inside it, and the
    targets of the links inside an input folder (frames or a ground truth kept elsewhere) are inputs too.

    Args:
        path: the output folder as the user gave it.
        inputs: (description, path) pairs, e.g. ``("the input recording", "REC")``; None paths are skipped. A
            preset name is no path: leave it out.
        name: how the message names the output folder, e.g. ``"--out"``.

    >>> check_inputs_apart("REC/images", [("the input recording", "REC")], name="--out")
    Traceback (most recent call last):
    ...
    ValueError: --out REC/images lies inside the input recording REC; choose a folder outside every input
    """
    out = _real(path)
    try:
        cwd = _real(os.getcwd())
    except OSError:  # the working folder was deleted: nothing there to protect
        cwd = None
    if cwd is not None and _within(cwd, out):
        where = "is" if out == cwd else "contains"
        raise ValueError(f"{name} {path} {where} the working folder {cwd}; choose a new folder for the output, e.g. "
                         f"a subfolder of the working folder")
    outs = _spellings(path)  # REC/images, where images links elsewhere, still lies inside REC
    for description, given in [*inputs, ("the evio_lib package", _PACKAGE_DIR)]:
        if given is None or str(given) == "":
            continue
        sources = [(description, str(given), source) for source in _spellings(given)]
        if description != "the evio_lib package":  # what the input's links point to is read too
            sources += [(f"the target of {description}'s link", link, target) for link, target in _link_targets(given)]
        for what, shown, source in sources:
            relation = None
            for candidate in outs:
                if candidate == source:
                    relation = "is"
                elif _within(candidate, source):
                    relation = relation or "lies inside"
                elif _within(source, candidate):
                    relation = relation or "contains"
            if relation is None:
                continue
            if what == "the evio_lib package" and relation == "lies inside" and not os.path.lexists(path):
                continue  # a new folder below the package (e.g. for new weights) replaces nothing of it
            raise ValueError(f"{name} {path} {relation} {what} {shown}; choose a folder outside every input")


def check_output_dir(path: str | Path, force: bool = False, *, inputs: Iterable[tuple[str, str | Path | None]] = (),
                     name: str = "output folder") -> Path:
    """Return ``Path(path)`` after checking that a command may write its output folder there.

    Args:
        path: the output folder (may not exist yet; missing parents are allowed).
        force: allow an existing non-empty folder (it will be replaced).
        inputs: the command's input paths as (description, path) pairs (see :func:`check_inputs_apart`).
        name: how messages about the inputs name the output folder, e.g. ``"--out"``.

    Raises:
        OutputExistsError (a ValueError): ``path`` is a folder that holds files and ``force`` is False.
        ValueError: ``path`` is empty, the working folder or contains it, is, contains or lies inside an input (all
            of these with or without ``force``); ``path`` exists and is not a folder; or the nearest existing parent
            folder is not a folder or not writable (the output and its temporary sibling could not be created there).
    """
    if not isinstance(path, (str, os.PathLike)) or str(path) == "":
        raise ValueError(f"output folder must be a path; got {path!r}")
    check_inputs_apart(path, inputs, name)
    path = Path(path)
    if path.exists() or path.is_symlink():
        if not path.is_dir():
            raise ValueError(f"output path {path} exists and is not a folder; expected a new or empty folder")
        if not force and any(path.iterdir()):
            raise OutputExistsError(f"output folder {path} already exists and is not empty; use --force to replace it")
        if force and not os.access(path, os.W_OK | os.X_OK) and any(path.iterdir()):
            raise ValueError(f"cannot replace output folder {path}: the folder is not writable, so its old content "
                             f"could not be removed; make it writable or choose another folder")
    parent = _nearest_existing(Path(os.path.abspath(path)).parent)
    if not parent.is_dir():
        raise ValueError(f"cannot create output folder {path}: {parent} is a file, not a folder")
    if not os.access(parent, os.W_OK | os.X_OK):
        raise ValueError(f"cannot create output folder {path}: the folder {parent} is not writable")
    try:  # os.access says yes to root everywhere; /proc, /sys, read-only mounts refuse only a real mkdir
        os.rmdir(tempfile.mkdtemp(prefix=".evio-probe-", dir=parent))
    except OSError as error:
        raise ValueError(f"cannot create output folder {path}: {parent} refuses new folders "
                         f"({error.strerror or type(error).__name__}); choose a folder on a writable disk") from None
    return path


def _default_mode() -> int:
    """Return the permission bits a plain ``mkdir`` gives now (0o777 less the umask)."""
    umask = os.umask(0)
    os.umask(umask)
    return 0o777 & ~umask


def _remove_created(created: list[Path]) -> None:
    """Remove the parent folders this module created, innermost first, while they are empty."""
    for folder in reversed(created):
        try:
            folder.rmdir()
        except OSError:
            break


def _commit(tmp: Path, target: Path, force: bool) -> None:
    """Move the finished ``tmp`` folder to ``target``; with ``force`` an existing target is replaced.

    The old target is renamed aside first, the new folder renamed in, and only then the old one deleted, so at
    every instant either the old or the new complete folder sits at ``target``.
    """
    if force and target.exists() and not (target.is_dir() and not any(target.iterdir())):
        aside = target.parent / f".{target.name}.old-{secrets.token_hex(4)}"
        os.rename(target, aside)
        try:
            os.rename(tmp, target)
        except BaseException:
            os.rename(aside, target)  # put the old folder back
            raise
        if aside.is_dir() and not aside.is_symlink():
            shutil.rmtree(aside)
        else:
            aside.unlink()
        return
    try:
        os.rename(tmp, target)  # POSIX: succeeds when target is absent or an empty folder
    except OSError as error:
        if target.exists() and target.is_dir() and any(target.iterdir()):
            raise OutputExistsError(
                f"output folder {target} was filled by something else while this command ran; use --force to replace it"
            ) from error
        raise


@contextmanager
def atomic_output_dir(path: str | Path, force: bool = False) -> Iterator[Path]:
    """Yield a temporary folder beside ``path`` that replaces ``path`` when the ``with`` block ends normally.

    Args:
        path: the output folder (checked with :func:`check_output_dir` first).
        force: replace an existing non-empty folder; the old one is removed only after the new one is complete.

    Yields:
        an empty folder ``<parent>/.<name>.tmp-XXXX`` to write everything into.

    On an exception (KeyboardInterrupt included) the temporary folder is deleted, parents this call created are
    removed again, the exception propagates and ``path`` is untouched.
    """
    target = Path(os.path.abspath(check_output_dir(path, force)))
    created: list[Path] = []
    parent = target.parent
    for folder in reversed([parent, *parent.parents]):  # create missing parents, remembering which
        if not folder.exists():
            folder.mkdir()
            created.append(folder)
    tmp = None
    try:
        tmp = Path(tempfile.mkdtemp(prefix=f".{target.name}.tmp-", dir=parent))
        os.chmod(tmp, _default_mode())  # mkdtemp makes 0o700; the result should look like a plain mkdir's
        yield tmp
        _commit(tmp, target, force)
    except BaseException:
        if tmp is not None and tmp.exists():
            shutil.rmtree(tmp, ignore_errors=True)
        _remove_created(created)
        raise
