"""Checkpoints (``map.pt``): torch.save of a state dict, written atomically, read safely.

The file holds ``{"eslam_checkpoint": CHECKPOINT_VERSION, "state": state}``. The state
may contain only tensors, numbers, booleans, strings, None, and lists, tuples and
dicts of those: :func:`save_checkpoint` refuses anything else, so every checkpoint
loads with ``torch.load(weights_only=True)``, which runs no code from the file.
"""

from __future__ import annotations

import pickle
import zipfile
from pathlib import Path

import torch

from eslam.atomic import write_with
from eslam.errors import InputError

CHECKPOINT_VERSION = 2
"""Format version of the checkpoint layout; bumped when the state's keys change meaning
(2: the trajectory record replaced the preallocated pose array and keyframe poses)."""
VERSION_KEY = "eslam_checkpoint"
"""Key of the format version in the saved file."""
_LEAF_TYPES = (torch.Tensor, bool, int, float, str, type(None))
_FIX_CORRUPT = "the file is damaged or not written by eslam; start a new run"


def _check_state(value: object, where: str) -> None:
    """Raise TypeError, naming the key path, for a value weights_only loading refuses."""
    if isinstance(value, dict):
        for key, item in value.items():
            if not isinstance(key, (str, int)):
                raise TypeError(f"checkpoint key {where}[{key!r}] must be a str or int")
            _check_state(item, f"{where}[{key!r}]")
    elif isinstance(value, (list, tuple)):
        for index, item in enumerate(value):
            _check_state(item, f"{where}[{index}]")
    elif not isinstance(value, _LEAF_TYPES):
        raise TypeError(
            f"checkpoint value {where} is a {type(value).__name__}: only tensors, numbers, "
            "strings, None, and lists, tuples and dicts of them can be saved"
        )


def save_checkpoint(path: str | Path, state: dict) -> None:
    """Save ``state`` to ``path`` atomically (temporary file, then ``os.replace``).

    Tensors are saved as they are (device included); move them to the CPU first for
    a file that loads anywhere (:func:`load_checkpoint` maps them in any case). Save
    views of large buffers as compact copies: torch.save writes a view's whole storage.

    Raises:
        TypeError: ``state`` holds a value other than tensors, numbers, strings, None,
            lists, tuples and dicts (the message names where).
    """
    if not isinstance(state, dict):
        raise TypeError(f"checkpoint state must be a dict, got {type(state).__name__}")
    _check_state(state, "state")
    payload = {VERSION_KEY: CHECKPOINT_VERSION, "state": state}
    write_with(path, lambda tmp: torch.save(payload, tmp))


def _to_device(value: object, device: torch.device) -> object:
    if isinstance(value, torch.Tensor):
        return value.to(device)
    if isinstance(value, dict):
        return {key: _to_device(item, device) for key, item in value.items()}
    if isinstance(value, list):
        return [_to_device(item, device) for item in value]
    if isinstance(value, tuple):
        return tuple(_to_device(item, device) for item in value)
    return value


def _load_failure(error: Exception) -> str:
    """One short line on why torch.load failed (its own messages run to paragraphs)."""
    if isinstance(error, pickle.UnpicklingError):
        return "not a torch file, or it holds objects other than tensors and plain values"
    if isinstance(error, EOFError):
        return "the file is empty or cut short"
    lines = str(error).strip().splitlines()
    first = lines[0] if lines else type(error).__name__
    return f"cannot be read: {first[:120]}"


def load_checkpoint(path: str | Path, map_location: str | torch.device | None = "cpu") -> dict:
    """Load a checkpoint written by :func:`save_checkpoint`.

    The file is read onto the CPU with ``weights_only=True``; tensors are then moved
    to ``map_location`` (so a device error is not mistaken for a damaged file).

    Args:
        path: the checkpoint file (a run's ``map.pt``).
        map_location: device of the returned tensors; None or "cpu" keeps them on the CPU.

    Returns:
        The ``state`` dict that was saved.

    Raises:
        InputError: the file is missing, unreadable, not an eslam checkpoint, or of
            another format version.
    """
    path = Path(path)
    if not path.is_file():
        raise InputError(path, "not found", "check the path, or run `eslam run` to make a map")
    try:
        payload = torch.load(path, map_location="cpu", weights_only=True)
    except (
        RuntimeError,
        OSError,
        EOFError,
        ValueError,
        pickle.UnpicklingError,
        zipfile.BadZipFile,
    ) as error:
        raise InputError(path, f"not an eslam map ({_load_failure(error)})", _FIX_CORRUPT) from None
    if not isinstance(payload, dict) or VERSION_KEY not in payload or "state" not in payload:
        raise InputError(path, "not an eslam map (no eslam checkpoint header)", _FIX_CORRUPT)
    version = payload[VERSION_KEY]
    if version != CHECKPOINT_VERSION:
        raise InputError(
            path,
            f"map format version {version}, but this eslam reads version {CHECKPOINT_VERSION}",
            "open it with the eslam version that wrote it, or start a new run",
        )
    state = payload["state"]
    if map_location is None or torch.device(map_location) == torch.device("cpu"):
        return state
    return _to_device(state, torch.device(map_location))
