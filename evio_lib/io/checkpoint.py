"""One reader for every torch checkpoint of evio: refuses, with one line naming the file, anything it cannot use.

:func:`read_checkpoint` is how the SuperPoint CNN (``run --weights``, ``table --events-cnn``, ``create_detector(...,
weights=...)``, ``features-train`` init and resume) and the event-to-image reconstructors (``reconstruct --method``,
``reconstruct-train --init-from`` and ``--resume``) open their files. It refuses, each with a :class:`CheckpointError`
(a ValueError) "FILE: problem; expected FORM":

- a missing file or a folder (:class:`CheckpointNotFoundError`, also a FileNotFoundError);
- an empty file, a truncated or damaged torch archive (the zip's CRC-32 of every member is checked before loading, so
  a flipped byte in the weights is caught too), a file that is no torch file at all, a plain Python pickle, a pickle of
  something ``weights_only`` loading refuses;
- a torch file that holds no dict (a bare tensor, a list);
- a checkpoint of another kind (a reconstructor given as SuperPoint weights and vice versa: the ``format`` tag each
  writer stores, else the keys it needs).

:func:`load_state` puts a state dict into a network and turns ``load_state_dict``'s RuntimeError (missing or
unexpected keys, a tensor of another shape: a network of another width) into a CheckpointError naming the file and the
first mismatches.
"""
from __future__ import annotations

import pickle
import warnings
import zipfile
from dataclasses import dataclass
from pathlib import Path
from typing import Any

__all__ = ["CHECKPOINT_KINDS", "CheckpointError", "CheckpointNotFoundError", "CheckpointKind", "read_checkpoint",
           "load_state"]


class CheckpointError(ValueError):
    """A checkpoint file cannot be used; the message is one line "FILE: problem; expected FORM"."""


class CheckpointNotFoundError(CheckpointError, FileNotFoundError):
    """The checkpoint file does not exist (a CheckpointError and a FileNotFoundError)."""


@dataclass(frozen=True)
class CheckpointKind:
    """What one kind of evio checkpoint looks like.

    Attributes:
        name: how messages call it ("SuperPoint checkpoint").
        format: the ``format`` tag its writer stores.
        required: keys the dict must hold.
        writer: what writes it (said in the messages).
        legacy_untagged: a dict without ``format`` but with the required keys is accepted (files written before the
            tag existed).
    """

    name: str
    format: str
    required: tuple[str, ...]
    writer: str
    legacy_untagged: bool = False

    def expected(self) -> str:
        """Return "a SuperPoint checkpoint written by ... (a torch dict with format ...)"."""
        return f"a {self.name} written by {self.writer} (a torch dict with format {self.format!r})"


#: The checkpoint kinds evio writes, by the name given to :func:`read_checkpoint`.
CHECKPOINT_KINDS: dict[str, CheckpointKind] = {
    "superpoint": CheckpointKind("SuperPoint checkpoint", "evio-superpoint-1", ("model_config", "state_dict"),
                                 "features-train or save_checkpoint",
                                 legacy_untagged=True),
    "reconstructor": CheckpointKind("reconstructor checkpoint", "evio-reconstructor-v1",
                                    ("architecture", "num_bins", "state_dict"),
                                    "reconstruct-train"),
}

_ZIP_MAGIC = b"PK\x03\x04"


def _first_line(error: BaseException, limit: int = 120) -> str:
    """Return ``TypeName: first sentence`` of an exception (torch's messages run for lines)."""
    lines = [line.strip() for line in str(error).splitlines() if line.strip()]
    detail = lines[0].split(". ")[0][:limit] if lines else ""
    return f"{type(error).__name__}{': ' + detail if detail else ''}"


def _kind_of(checkpoint: dict) -> str | None:
    """Return the name of the kind a checkpoint dict belongs to (by its format tag, else its keys), or None."""
    for name, kind in CHECKPOINT_KINDS.items():
        if checkpoint.get("format") == kind.format:
            return name
    for name, kind in CHECKPOINT_KINDS.items():
        if "format" not in checkpoint and all(k in checkpoint for k in kind.required):
            return name
    return None


def _damage(path: Path, head: bytes) -> str | None:
    """Return why a torch zip archive is damaged (truncated, a member failing its CRC), or None when it is whole."""
    if not head.startswith(_ZIP_MAGIC):
        return None
    try:
        with zipfile.ZipFile(path) as archive:
            bad = archive.testzip()  # reads every member and checks its CRC-32
    except (zipfile.BadZipFile, EOFError, OSError, ValueError) as error:
        return f"a truncated or damaged torch archive ({_first_line(error)})"
    if bad is not None:
        return f"a damaged torch archive (member {bad} fails its CRC check)"
    return None


def read_checkpoint(path: str | Path, kind: str, *, map_location: Any = "cpu", weights_only: bool = True,
                    check_archive: bool = True) -> dict[str, Any]:
    """Return the checkpoint dict in ``path`` after checking it is a whole file of ``kind``.

    Args:
        path: the file.
        kind: a key of :data:`CHECKPOINT_KINDS` ("superpoint", "reconstructor").
        map_location: passed to ``torch.load``.
        weights_only: passed to ``torch.load`` (True: plain data and tensors only, no code runs).
        check_archive: verify the CRC-32 of every member of the zip archive first (a few ms for 5 MB).

    Raises:
        CheckpointNotFoundError: the file does not exist or is not a file.
        CheckpointError: anything else that makes the file unusable (module docstring), one line naming the file.

    >>> read_checkpoint("/no/such.pt", "superpoint")
    Traceback (most recent call last):
    ...
    evio_lib.io.checkpoint.CheckpointNotFoundError: /no/such.pt: file not found; expected a SuperPoint checkpoint written by features-train or save_checkpoint (a torch dict with format 'evio-superpoint-1')
    """
    import torch

    if kind not in CHECKPOINT_KINDS:
        raise ValueError(f"kind must be one of {sorted(CHECKPOINT_KINDS)}; got {kind!r}")
    spec = CHECKPOINT_KINDS[kind]
    path = Path(path)
    expected = f"expected {spec.expected()}"
    if not path.exists():
        raise CheckpointNotFoundError(f"{path}: file not found; {expected}")
    if not path.is_file():
        raise CheckpointNotFoundError(f"{path}: not a file; {expected}")
    try:
        with open(path, "rb") as f:
            head = f.read(8)
    except OSError as error:
        raise CheckpointError(f"{path}: cannot be read ({_first_line(error)}); {expected}") from None
    if not head:
        raise CheckpointError(f"{path}: the file is empty; {expected}")
    problem = _damage(path, head) if check_archive else None
    if problem is None:
        try:
            with warnings.catch_warnings():  # "Detected pickle protocol 4": the error below says more
                warnings.simplefilter("ignore", UserWarning)
                checkpoint = torch.load(path, map_location=map_location, weights_only=weights_only)
        except Exception as error:  # torch.load raises pickle, EOF, zip (RuntimeError) and other errors
            if head.startswith(_ZIP_MAGIC) and weights_only and isinstance(error, pickle.UnpicklingError):
                # the archive is whole (its CRCs passed): what failed is torch's allow-list of pickled objects
                problem = (f"a torch archive holding Python objects other than tensors, numbers, strings and "
                           f"containers, refused unread because loading them could run code (torch.load: "
                           f"{_first_line(error)})")
            elif head.startswith(_ZIP_MAGIC):
                problem = f"a truncated or damaged torch archive (torch.load: {_first_line(error)})"
            elif head[:1] == b"\x80" and isinstance(error, (RuntimeError, pickle.UnpicklingError, EOFError)):
                problem = f"a plain Python pickle, not a file written by torch.save (torch.load: {_first_line(error)})"
            else:
                problem = f"not a torch checkpoint file (it starts with {head!r}; torch.load: {_first_line(error)})"
    if problem is not None:
        raise CheckpointError(f"{path}: not a readable {spec.name}: {problem}; {expected}")
    if not isinstance(checkpoint, dict):
        raise CheckpointError(f"{path}: holds a {type(checkpoint).__name__}, not a checkpoint dict; {expected}")
    found = _kind_of(checkpoint)
    if found is not None and found != kind:
        other = CHECKPOINT_KINDS[found]
        raise CheckpointError(f"{path}: is a {other.name} (written by {other.writer}), not a {spec.name}; {expected}")
    tag = checkpoint.get("format")
    if tag is not None and tag != spec.format:
        raise CheckpointError(f"{path}: has format {tag!r}, not a {spec.name}; {expected}")
    if tag is None and not spec.legacy_untagged:
        raise CheckpointError(f"{path}: has no 'format' entry (keys {sorted(map(str, checkpoint))[:8]}); {expected}")
    missing = [k for k in spec.required if k not in checkpoint]
    if missing:
        raise CheckpointError(f"{path}: not a {spec.name}: lacks {missing} (keys {sorted(map(str, checkpoint))[:8]}); {expected}")
    if not isinstance(checkpoint["state_dict"], dict):
        raise CheckpointError(f"{path}: its state_dict is a {type(checkpoint['state_dict']).__name__}, not a dict of "
                              f"tensors; {expected}")
    return checkpoint


def load_state(module: Any, state: dict, path: str | Path,
               problem: str = "its state_dict does not fit the network", strict: bool = True) -> Any:
    """Load ``state`` into ``module`` (a torch Module or optimizer); a state that does not fit is a CheckpointError.

    The message is one line "FILE: PROBLEM (the first mismatches: missing and unexpected keys, tensors of another
    shape)". Returns what ``load_state_dict`` returns.
    """
    try:
        return module.load_state_dict(state, strict=strict) if strict is not True else module.load_state_dict(state)
    except (RuntimeError, ValueError, KeyError, TypeError, IndexError) as error:
        lines = [line.strip() for line in str(error).splitlines() if line.strip()]
        body = " ".join(lines[1:] if len(lines) > 1 and lines[0].startswith("Error(s) in loading") else lines)
        body = body.replace("\t", " ")
        if len(body) > 300:
            body = body[:297] + "..."
        raise CheckpointError(f"{path}: {problem} ({type(error).__name__}: {body})") from None
