"""Reading the files of an agent folder nobody vouches for: bounded, regular, strictly typed.

An agent folder (``agents.folder.format``, ``agents.marl.policy_folder``) or a
``cpf-export`` ONNX file may come from anyone, so every read here assumes the
worst:

- only a regular file is opened (``O_NOFOLLOW | O_NONBLOCK``, then ``fstat``): a
  FIFO, a device such as ``/dev/zero``, a socket or a folder is refused by what
  it is, without blocking or reading it; a symbolic link in a folder is
  followed only when it stays inside the folder, else it is refused, naming its
  target (an exported graph named on its own may be a link to a regular file);
- sizes are bounded before reading: ``MAX_JSON_BYTES`` (1 MiB) for each JSON
  file, ``MAX_WEIGHT_BYTES`` (256 MiB) for a weights or ONNX file;
- JSON is nested at most ``MAX_JSON_DEPTH`` (32) levels (checked before
  parsing, so no recursion limit is hit) and holds no ``NaN`` or ``Infinity``;
- values are typed strictly (``check_fields``): a JSON boolean is not a number,
  a string is not a number nor a boolean (``"false"`` is an error), numbers are
  finite.

Every failure is an ``AgentFolderError`` (a ``ValueError``) of one line that
names the file and, where there is one, the field.
"""

from __future__ import annotations

import errno
import hashlib
import json
import math
import os
import re
import stat
from collections.abc import Mapping
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import NDArray

__all__ = [
    "MAX_JSON_BYTES",
    "MAX_JSON_DEPTH",
    "MAX_WEIGHT_BYTES",
    "AgentFolderError",
    "check_fields",
    "field",
    "parse_json",
    "read_file",
    "read_manifest",
    "read_verified",
    "sha256",
    "statistics_arrays",
]

#: Largest JSON file read (config, normalization, manifest, ONNX metadata), bytes.
MAX_JSON_BYTES = 1 << 20
#: Largest weights (safetensors) or ONNX file read, bytes: 64 M float32 parameters.
MAX_WEIGHT_BYTES = 256 << 20
#: Deepest JSON nesting read (the files of the format nest 3 levels).
MAX_JSON_DEPTH = 32

_KINDS = {
    stat.S_IFIFO: "a FIFO (named pipe)",
    stat.S_IFCHR: "a character device",
    stat.S_IFBLK: "a block device",
    stat.S_IFSOCK: "a socket",
    stat.S_IFDIR: "a folder",
}
_STRINGS = re.compile(rb'"(?:[^"\\]|\\.)*"')


class AgentFolderError(ValueError):
    """An agent folder (or exported file) that is incomplete, inconsistent or not of its format."""


def sha256(data: bytes) -> str:
    """The SHA-256 of ``data``, as 64 hex digits."""
    return hashlib.sha256(data).hexdigest()


def read_file(path: Path, limit: int, folder: Path | None = None) -> bytes:
    """The bytes of a regular file of at most ``limit`` bytes, read without blocking.

    Args:
        path: The file.
        limit: Largest size accepted, bytes.
        folder: The folder a symbolic link at ``path`` must resolve into; None: a file
            the user named on its own (an exported graph), whose links are followed.

    Raises:
        AgentFolderError: Missing, a link leaving ``folder``, not a regular file
            (FIFO, device, socket, folder), larger than ``limit``, or unreadable.
    """
    named = path
    if path.is_symlink():
        try:
            target = path.resolve(strict=True)
        except FileNotFoundError:
            raise AgentFolderError(f"{path} is a link to a missing {os.readlink(path)}.") from None
        except (OSError, RuntimeError):  # ELOOP; RuntimeError on Python 3.11
            raise AgentFolderError(f"{path} is a link loop; give the file itself.") from None
        if folder is not None and not target.is_relative_to(folder.resolve()):
            raise AgentFolderError(
                f"{path} is a link to {os.readlink(path)}, outside {folder}; an agent folder "
                "holds its files itself. Copy the file into the folder."
            )
        named, path = Path(f"{path} (a link to {target})"), target
    try:
        handle = os.open(path, os.O_RDONLY | os.O_NOFOLLOW | os.O_NONBLOCK | os.O_CLOEXEC)
    except FileNotFoundError:
        raise AgentFolderError(f"{named} is missing.") from None
    except OSError as error:
        if error.errno == errno.ELOOP:
            raise AgentFolderError(f"{named} is a link loop; give the file itself.") from None
        raise AgentFolderError(f"{named} cannot be opened: {error.strerror}.") from None
    try:
        info = os.fstat(handle)
        if not stat.S_ISREG(info.st_mode):
            kind = _KINDS.get(stat.S_IFMT(info.st_mode), "a special file")
            raise AgentFolderError(f"{named} is {kind}, not a regular file; it is not read.")
        if info.st_size > limit:
            raise AgentFolderError(
                f"{named} has {info.st_size:,} bytes, more than the {limit:,} this loader reads."
            )
        chunks, size = [], 0
        while size <= limit:
            chunk = os.read(handle, min(1 << 20, limit + 1 - size))
            if not chunk:
                break
            chunks.append(chunk)
            size += len(chunk)
    except OSError as error:
        raise AgentFolderError(f"{named} cannot be read: {error.strerror}.") from None
    finally:
        os.close(handle)
    if size > limit:
        raise AgentFolderError(f"{named} grew past the {limit:,} bytes this loader reads.")
    return b"".join(chunks)


def _refuse_constant(name: str) -> None:
    raise ValueError(f"{name} is not a JSON number")


def parse_json(data: bytes, source: Path | str) -> Any:
    """Parse JSON of at most ``MAX_JSON_DEPTH`` levels, without NaN or Infinity.

    Raises:
        AgentFolderError: Not UTF-8, nested too deep, or not JSON (naming ``source``).
    """
    if len(data) > MAX_JSON_BYTES:
        raise AgentFolderError(
            f"{source} has {len(data):,} bytes of JSON, more than the {MAX_JSON_BYTES:,} read."
        )
    skeleton = np.frombuffer(_STRINGS.sub(b'""', data), dtype=np.uint8)
    opens = (skeleton == ord("[")) | (skeleton == ord("{"))
    closes = (skeleton == ord("]")) | (skeleton == ord("}"))
    depth = np.cumsum(opens.astype(np.int64) - closes.astype(np.int64))
    if depth.size and int(depth.max()) > MAX_JSON_DEPTH:
        raise AgentFolderError(
            f"{source} nests JSON {int(depth.max())} levels deep; {MAX_JSON_DEPTH} are read."
        )
    try:
        return json.loads(data.decode("utf-8"), parse_constant=_refuse_constant)
    except UnicodeDecodeError as error:
        raise AgentFolderError(f"{source} is not UTF-8 text: {error.reason}.") from None
    except ValueError as error:  # JSONDecodeError, and the refused constants
        raise AgentFolderError(f"{source} is not valid JSON: {error}.") from None


def field(data: Any, key: str, source: Path | str, where: str = "") -> Any:
    """``data[key]`` of a JSON object, or an error naming the file and the field.

    Args:
        data: The parsed object (an error if it is not a dict).
        key: The field.
        source: The file, for messages.
        where: The object's own path in the file (``"task."``), for messages.
    """
    if not isinstance(data, dict):
        name = where.rstrip(".") or "the top level"
        raise AgentFolderError(f"{source}: {name} must be a JSON object, got {_kind(data)}.")
    if key not in data:
        raise AgentFolderError(f"{source} lacks the field '{where}{key}'.")
    return data[key]


def _kind(value: Any) -> str:
    names = {bool: "a boolean", str: "a string", list: "a list", dict: "an object"}
    if value is None:
        return "null"
    return f"{names.get(type(value), 'a number')} ({json.dumps(value)[:40]})"


def _is_int(value: Any) -> bool:
    return isinstance(value, int) and not isinstance(value, bool)


def _is_number(value: Any) -> bool:
    return isinstance(value, int | float) and not isinstance(value, bool) and math.isfinite(value)


def _is_strings(value: Any) -> bool:
    return isinstance(value, list) and all(isinstance(x, str) for x in value)


#: JSON checks of the annotations ``check_fields`` understands.
_CHECKS: dict[str, tuple[str, Any]] = {
    "str": ("a string", lambda v: isinstance(v, str)),
    "int": ("an integer", _is_int),
    "float": ("a finite number", _is_number),
    "bool": ("true or false", lambda v: isinstance(v, bool)),
    "str | None": ("a string or null", lambda v: v is None or isinstance(v, str)),
    "int | None": ("an integer or null", lambda v: v is None or _is_int(v)),
    "tuple[str, ...]": ("a list of strings", _is_strings),
    "tuple[int, ...]": (
        "a list of integers",
        lambda v: isinstance(v, list) and all(_is_int(x) for x in v),
    ),
    "str | tuple[str, ...]": (
        "a string or a list of strings",
        lambda v: isinstance(v, str) or _is_strings(v),
    ),
    "tuple[float, float, float]": (
        "a list of three finite numbers",
        lambda v: isinstance(v, list) and len(v) == 3 and all(_is_number(x) for x in v),
    ),
    "dict[str, float]": (
        "an object of finite numbers",
        lambda v: isinstance(v, dict) and all(_is_number(x) for x in v.values()),
    ),
}


def check_fields(
    data: Any, types: Mapping[str, str], source: Path | str, where: str = "", required: bool = False
) -> None:
    """Check the JSON types of an object's fields against annotations (``"float"``, ...).

    Fields absent from ``data`` are skipped (their defaults apply) unless
    ``required``; fields not in ``types`` are left to the caller.

    Raises:
        AgentFolderError: A field of the wrong JSON type (a boolean or string for a number,
            a string for a boolean, a non-finite number...), naming file and field.
    """
    if not isinstance(data, dict):
        name = where.rstrip(".") or "the top level"
        raise AgentFolderError(f"{source}: {name} must be a JSON object, got {_kind(data)}.")
    for key, annotation in types.items():
        description, check = _CHECKS[annotation]  # a KeyError here: teach _CHECKS the type
        if key not in data:
            if required:
                raise AgentFolderError(f"{source} lacks the field '{where}{key}'.")
            continue
        if not check(data[key]):
            raise AgentFolderError(
                f"{source}: field '{where}{key}' must be {description}, got {_kind(data[key])}."
            )


def statistics_arrays(
    data: Any, source: Path | str
) -> tuple[NDArray[np.float64], NDArray[np.float64], float, float]:
    """(mean, var, epsilon, clip) of a ``normalization.json`` object, strictly checked.

    Raises:
        AgentFolderError: A missing or extra field, a non-number, a non-finite value,
            var < 0, epsilon or clip <= 0, or mean and var of different lengths.
    """
    check_fields(data, {"epsilon": "float", "clip": "float"}, source, required=True)
    extra = sorted(set(data) - {"mean", "var", "epsilon", "clip"})
    if extra:
        raise AgentFolderError(f"{source} has unknown field(s) {extra}.")
    arrays = []
    for key in ("mean", "var"):
        values = field(data, key, source)
        if not isinstance(values, list) or not all(_is_number(x) for x in values):
            raise AgentFolderError(
                f"{source}: field {key!r} must be a list of finite numbers, got "
                f"{_kind(values) if not isinstance(values, list) else 'other entries'}."
            )
        arrays.append(np.asarray(values, dtype=np.float64).reshape(-1))
    mean, var = arrays
    if var.shape != mean.shape:
        raise AgentFolderError(
            f"{source}: 'mean' has {mean.size} entries but 'var' has {var.size}; they must match."
        )
    if np.any(var < 0):
        raise AgentFolderError(f"{source}: field 'var' has a negative entry; variances are >= 0.")
    for key in ("epsilon", "clip"):
        if data[key] <= 0:
            raise AgentFolderError(f"{source}: field {key!r} must be > 0, got {data[key]!r}.")
    return mean, var, float(data["epsilon"]), float(data["clip"])


def read_manifest(
    path: Path, format_name: str, format_version: int | tuple[int, ...]
) -> dict[str, Any]:
    """A manifest of ``format_name`` and a version this reader knows, its file list checked.

    Args:
        path: The manifest.
        format_name: The format it must name.
        format_version: The version it must give, or the versions read (a tuple).

    Raises:
        AgentFolderError: Unreadable, another format or version, or a malformed file list.
    """
    versions = (format_version,) if isinstance(format_version, int) else format_version
    manifest = parse_json(read_file(path, MAX_JSON_BYTES), path)
    name = field(manifest, "format", path)
    if name != format_name:
        raise AgentFolderError(f"{path} is a {name!r} manifest, not a {format_name!r} one.")
    version = field(manifest, "format_version", path)
    if not _is_int(version):
        raise AgentFolderError(
            f"{path}: field 'format_version' must be an integer, got {_kind(version)}."
        )
    if version not in versions:
        known = ", ".join(str(v) for v in versions)
        raise AgentFolderError(
            f"{path} has format version {version}; this cpf_env reads version(s) {known} only. "
            "Use the cpf_env that wrote it, or retrain."
        )
    files = field(manifest, "files", path)
    if not isinstance(files, dict) or not files:
        raise AgentFolderError(
            f"{path}: field 'files' must be an object of file name -> sha256 and bytes, got "
            f"{_kind(files)}."
        )
    for file, entry in files.items():
        check_fields(entry, {"sha256": "str", "bytes": "int"}, path, f"files.{file}.", True)
        if not re.fullmatch("[0-9a-f]{64}", entry["sha256"]) or entry["bytes"] < 0:
            raise AgentFolderError(
                f"{path}: field 'files.{file}' must give 64 hex digits and a size >= 0."
            )
    return manifest


def read_verified(
    folder: Path, name: str, manifest: dict[str, Any], limit: int, manifest_name: str
) -> bytes:
    """A file's bytes (at most ``limit``), checked against the manifest's size and hash.

    Raises:
        AgentFolderError: Not listed, not a regular file in the folder, too large, or
            not the file the manifest lists (named).
    """
    entry = manifest["files"].get(name)
    if entry is None:
        raise AgentFolderError(
            f"{folder / manifest_name} does not list {name}; the folder is damaged."
        )
    path = folder / name
    if not path.exists() and not path.is_symlink():
        raise AgentFolderError(f"{path} is missing; the manifest lists it. Copy the whole folder.")
    data = read_file(path, limit, folder)
    if len(data) != entry["bytes"] or sha256(data) != entry["sha256"]:
        raise AgentFolderError(
            f"{path} does not match its SHA-256 in {manifest_name}: it was edited, truncated or "
            "comes from another run. Use the folder as cpf-train wrote it."
        )
    return data
