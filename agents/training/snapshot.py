"""Data-only snapshots of training state: plain values, and the mutable state of an object graph.

A training checkpoint must hold everything that changes while an agent
learns (the simulator's arrays, the base policy's adaptive weights, the
random generators, the normalization statistics, SB3's counters and
optimizer moments) and must be readable without running code: no pickle.
This module turns such state into a JSON tree plus a dict of arrays
(numpy arrays and torch tensors, stored by the caller as ``.npz`` and
safetensors), and back.

Two operations:

- ``encode_value`` / ``decode_value``: a plain value (nested dicts, lists,
  tuples, scalars, numpy arrays and scalars, torch tensors) to a tree and back,
  e.g. an optimizer's ``state_dict`` or ``np.random.get_state()``.
- ``capture`` / ``restore``: the state of an object graph (an SB3 vector env
  and everything under it) written into a freshly built graph of the same
  structure. Objects of this project, SB3 and Gymnasium are walked field by
  field; arrays are copied in place (views of a shared buffer stay views);
  numpy ``Generator`` states are set in place; frozen dataclasses (a
  ``Scenario``, a ``ResidualConfig``), functions, compiled kernels and other
  immutable parts are configuration, rebuilt identically from the training
  configuration, and are not stored. An object reached twice is stored once
  and must be the same object again in the fresh graph. Anything else (an
  object of an unknown library) is refused with its path, so a checkpoint
  never silently misses state.

Example:
    >>> import numpy as np
    >>> arrays = {}
    >>> tree = encode_value({"step": 3, "x": np.arange(2.0)}, "s", arrays)
    >>> decode_value(tree, arrays)["x"]
    array([0., 1.])
"""

from __future__ import annotations

import abc
import collections
import types
from typing import Any

import numpy as np
import torch

__all__ = ["SnapshotError", "capture", "decode_value", "encode_value", "restore"]

#: Modules whose objects are walked field by field.
WALKED_MODULES = ("cpf_env", "baselines", "agents", "stable_baselines3", "gymnasium")
#: Values that cannot change in place: stored by value, never by reference.
IMMUTABLE = (type(None), bool, int, float, str)
#: Parts that are configuration or code: rebuilt from the configuration, not stored.
FIXED = (
    types.FunctionType,
    types.BuiltinFunctionType,
    types.MethodType,
    types.MethodDescriptorType,
    types.WrapperDescriptorType,
    types.GetSetDescriptorType,
    types.MappingProxyType,
    types.GenericAlias,
    types.UnionType,
    types.ModuleType,
    type,
    property,
    frozenset,
    np.dtype,
    torch.device,
    type(abc.ABC._abc_impl),  # type: ignore[attr-defined]  # the ABC machinery's cache
)


class SnapshotError(ValueError):
    """State that cannot be stored as data, or a fresh object graph that does not fit it."""


def encode_value(value: Any, path: str, arrays: dict[str, Any]) -> Any:
    """A plain value as a JSON-ready tree; its arrays and tensors go into ``arrays``.

    Args:
        value: Nested dicts (str or int keys), lists, tuples, deques, scalars,
            numpy arrays and scalars, torch tensors.
        path: A unique name for this value (the arrays' keys start with it).
        arrays: Receives ``key -> numpy array or torch tensor``.

    Raises:
        SnapshotError: A value of another type (named by its path).
    """
    if isinstance(value, IMMUTABLE):
        return {"v": value}
    if isinstance(value, np.generic):
        return {"np": value.dtype.str, "v": value.item()}
    if isinstance(value, np.ndarray):
        if value.dtype.hasobject:
            raise SnapshotError(f"{path} is an object array; only numeric arrays are data.")
        arrays[path] = np.ascontiguousarray(value).copy()
        return {"array": path}
    if isinstance(value, torch.Tensor):
        arrays[path] = value.detach().cpu().contiguous().clone()
        return {"tensor": path}
    if isinstance(value, dict):
        for key in value:
            if not isinstance(key, str | int) or isinstance(key, bool):
                raise SnapshotError(f"{path} has a key {key!r}; only str and int keys are data.")
        return {
            "dict": [[k, encode_value(v, f"{path}.{k}", arrays)] for k, v in value.items()],
            "kind": "ordered" if isinstance(value, collections.OrderedDict) else "dict",
        }
    if isinstance(value, list | tuple | collections.deque):
        kind = {list: "list", tuple: "tuple", collections.deque: "deque"}.get(type(value))
        if kind is None:
            raise SnapshotError(f"{path} is a {type(value).__name__}; give a plain sequence.")
        node: dict[str, Any] = {
            kind: [encode_value(v, f"{path}[{i}]", arrays) for i, v in enumerate(value)]
        }
        if isinstance(value, collections.deque):
            node["maxlen"] = value.maxlen
        return node
    raise SnapshotError(f"{path} is a {type(value).__qualname__}, which is not plain data.")


def decode_value(node: Any, arrays: dict[str, Any]) -> Any:
    """The value ``encode_value`` stored as ``node`` (new objects, nothing shared)."""
    if "v" in node:
        return np.dtype(node["np"]).type(node["v"]) if "np" in node else node["v"]
    if "array" in node:
        return np.array(arrays[node["array"]])
    if "tensor" in node:
        return arrays[node["tensor"]].clone()
    if "dict" in node:
        items = [(k, decode_value(v, arrays)) for k, v in node["dict"]]
        return collections.OrderedDict(items) if node["kind"] == "ordered" else dict(items)
    if "list" in node:
        return [decode_value(v, arrays) for v in node["list"]]
    if "tuple" in node:
        return tuple(decode_value(v, arrays) for v in node["tuple"])
    if "deque" in node:
        return collections.deque((decode_value(v, arrays) for v in node["deque"]), node["maxlen"])
    raise SnapshotError(f"unknown snapshot node {sorted(node)}; the checkpoint is damaged.")


def _is_fixed(value: Any) -> bool:
    """Configuration or code: rebuilt identically, not stored."""
    params = getattr(type(value), "__dataclass_params__", None)
    if isinstance(value, FIXED) or (params is not None and params.frozen):
        return True
    module = type(value).__module__
    return callable(value) and not module.startswith(WALKED_MODULES)


def _fields(value: Any) -> dict[str, Any]:
    """An object's instance attributes (``__dict__`` and ``__slots__``)."""
    fields = dict(getattr(value, "__dict__", {}))
    for cls in type(value).__mro__:
        for slot in getattr(cls, "__slots__", ()):
            if slot not in ("__dict__", "__weakref__") and hasattr(value, slot):
                fields[slot] = getattr(value, slot)
    return fields


class _Capture:
    """Walks an object graph once, recording the path of every mutable object seen."""

    def __init__(self, arrays: dict[str, Any]) -> None:
        self.arrays = arrays
        self.seen: dict[int, str] = {}
        self.keep: list[Any] = []  # keeps walked objects alive so their ids stay unique

    def node(self, value: Any, path: str) -> Any:
        if isinstance(value, (*IMMUTABLE, np.generic)):
            return encode_value(value, path, self.arrays)
        if id(value) in self.seen:
            return {"ref": self.seen[id(value)]}
        self.seen[id(value)] = path
        self.keep.append(value)
        if isinstance(value, np.ndarray | torch.Tensor):
            return encode_value(value, path, self.arrays)
        if isinstance(value, np.random.Generator):
            return {"generator": encode_value(value.bit_generator.state, path, self.arrays)}
        if _is_fixed(value):
            return {"fixed": type(value).__qualname__}
        if isinstance(value, dict):
            return {"dict": [[k, self.node(v, f"{path}.{k}")] for k, v in value.items()]}
        if isinstance(value, list | collections.deque):
            return {"list": [self.node(v, f"{path}[{i}]") for i, v in enumerate(value)]}
        if isinstance(value, tuple):
            return {"tuple": [self.node(v, f"{path}[{i}]") for i, v in enumerate(value)]}
        if type(value).__module__.startswith(WALKED_MODULES):
            return {
                "object": type(value).__qualname__,
                "fields": {k: self.node(v, f"{path}.{k}") for k, v in _fields(value).items()},
            }
        raise SnapshotError(
            f"{path} is a {type(value).__module__}.{type(value).__qualname__}, whose state a "
            "checkpoint cannot store as data; keep such objects out of the training env."
        )


def capture(root: Any, name: str, arrays: dict[str, Any]) -> Any:
    """The mutable state of the graph under ``root`` as a tree; arrays go into ``arrays``.

    Args:
        root: The object graph (e.g. SB3's wrapped vector env).
        name: Prefix of every path (and array key).
        arrays: Receives ``key -> numpy array`` (or torch tensor).

    Raises:
        SnapshotError: A part that is neither walkable, plain data nor configuration.
    """
    return _Capture(arrays).node(root, name)


class _Restore:
    """Writes a captured tree into a fresh graph of the same structure."""

    def __init__(self, arrays: dict[str, Any]) -> None:
        self.arrays = arrays
        self.at: dict[str, Any] = {}
        self.written: dict[int, Any] = {}  # arrays of the fresh graph already overwritten

    def node(self, current: Any, node: Any, path: str) -> Any:
        """The restored value of ``current`` (the same object, changed in place, if mutable)."""
        if "ref" in node:  # the captured graph shared this object: share it again
            if node["ref"] not in self.at:
                raise SnapshotError(f"{path} refers to {node['ref']}, which the checkpoint lacks.")
            return self.at[node["ref"]]
        if "v" in node:
            return decode_value(node, self.arrays)
        self.at[path] = current
        if "array" in node or "tensor" in node:
            saved = decode_value(node, self.arrays)
            same_form = (
                isinstance(current, np.ndarray)
                and isinstance(saved, np.ndarray)
                and current.shape == saved.shape
                and current.dtype == saved.dtype
            )
            if (
                same_form
                and not current.flags.writeable
                and np.array_equal(current, saved, equal_nan=True)
            ):
                return current  # a read-only constant (a policy's parameters), as saved
            if (
                same_form
                and current.flags.writeable
                and id(current) not in self.written  # shared in the fresh graph only: split
            ):
                np.copyto(current, saved)
                self.written[id(current)] = current
                return current
            self.at[path] = saved
            return saved
        if "generator" in node:
            if not isinstance(current, np.random.Generator):
                raise self._mismatch(path, "a numpy Generator", current)
            current.bit_generator.state = decode_value(node["generator"], self.arrays)
            return current
        if "fixed" in node:
            if type(current).__qualname__ != node["fixed"]:
                raise self._mismatch(path, node["fixed"], current)
            return current
        if "dict" in node:
            if not isinstance(current, dict):
                raise self._mismatch(path, "a dict", current)
            restored = {k: self._child(current.get(k), v, f"{path}.{k}") for k, v in node["dict"]}
            current.clear()
            current.update(restored)
            return current
        if "list" in node:
            if not isinstance(current, list | collections.deque):
                raise self._mismatch(path, "a list", current)
            old = list(current)
            items = [
                self._child(old[i] if i < len(old) else None, v, f"{path}[{i}]")
                for i, v in enumerate(node["list"])
            ]
            current.clear()
            current.extend(items)
            return current
        if "tuple" in node:
            if not isinstance(current, tuple) or len(current) != len(node["tuple"]):
                raise self._mismatch(path, f"a tuple of {len(node['tuple'])}", current)
            pairs = zip(current, node["tuple"], strict=True)
            items = [self.node(c, v, f"{path}[{i}]") for i, (c, v) in enumerate(pairs)]
            if all(a is b for a, b in zip(items, current, strict=True)):
                return current
            make = getattr(type(current), "_make", None)
            return make(items) if make is not None else tuple(items)
        if "object" in node:
            if type(current).__qualname__ != node["object"]:
                raise self._mismatch(path, node["object"], current)
            fields = _fields(current)
            for name, child in node["fields"].items():
                if name not in fields and not ("v" in child or "array" in child):
                    raise SnapshotError(f"{path}.{name} is missing in the fresh env.")
                value = self.node(fields.get(name), child, f"{path}.{name}")
                if value is not fields.get(name):
                    object.__setattr__(current, name, value)
            return current
        raise SnapshotError(f"unknown snapshot node {sorted(node)} at {path}; damaged checkpoint.")

    def _child(self, current: Any, node: Any, path: str) -> Any:
        if current is None and not ("v" in node or "array" in node or "ref" in node):
            raise SnapshotError(f"{path} is missing in the fresh env.")
        return self.node(current, node, path)

    @staticmethod
    def _mismatch(path: str, expected: str, current: Any) -> SnapshotError:
        return SnapshotError(
            f"{path} is a {type(current).__qualname__} in the fresh env but was {expected} "
            "when the checkpoint was written; resume with the code and configuration that "
            "wrote it."
        )


def restore(root: Any, tree: Any, name: str, arrays: dict[str, Any]) -> None:
    """Write the state ``capture`` recorded into ``root``, a freshly built graph.

    Args:
        root: A graph built as the captured one was (same configuration and code).
        tree: ``capture``'s tree.
        name: The prefix given to ``capture``.
        arrays: The arrays ``capture`` filled (as loaded back).

    Raises:
        SnapshotError: The fresh graph's structure differs from the captured one.
    """
    result = _Restore(arrays).node(root, tree, name)
    if result is not root:
        raise SnapshotError(f"{name} could not be restored in place.")
