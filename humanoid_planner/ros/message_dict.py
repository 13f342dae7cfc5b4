"""ROS messages <-> plain dicts (for YAML), for any generated message type.

The equivalent of rosidl_runtime_py's `set_message_fields` / `message_to_ordereddict`, which are
not available as wheels here. Field names and nesting mirror the .msg definitions; numbers may be
given as ints where floats are expected; unknown field names are errors that list the known ones.
"""
from __future__ import annotations

import array
import importlib
from typing import Any

import numpy as np
from rosidl_parser.definition import (AbstractNestedType, AbstractGenericString, BasicType, NamespacedType)

_FLOATS = {"float", "double", "long double"}
_INTS = {"char": (0, 255), "octet": (0, 255), "int8": (-2**7, 2**7 - 1), "uint8": (0, 2**8 - 1),
         "int16": (-2**15, 2**15 - 1), "uint16": (0, 2**16 - 1), "int32": (-2**31, 2**31 - 1),
         "uint32": (0, 2**32 - 1), "int64": (-2**63, 2**63 - 1), "uint64": (0, 2**64 - 1)}


class MessageFieldError(ValueError):
    """A dict that does not fit the message type (the message names the field path)."""


def _fields(msg) -> list[tuple[str, Any]]:
    return list(zip(msg.get_fields_and_field_types().keys(), msg.SLOT_TYPES))


def _class(t: NamespacedType):
    module = importlib.import_module(".".join(t.namespaces))
    return getattr(module, t.name)


def _scalar(t, value, path: str):
    if isinstance(t, AbstractGenericString):
        if not isinstance(value, (str, int, float)):
            raise MessageFieldError(f"{path}: expected a string, got {type(value).__name__}")
        return str(value)
    if isinstance(t, BasicType):
        name = t.typename
        try:
            if name in _FLOATS:
                if isinstance(value, str):  # YAML has .nan/.inf; accept "nan", "inf" too
                    return float(value)
                if isinstance(value, bool) or not isinstance(value, (int, float)):
                    raise TypeError
                return float(value)
            if name == "boolean":
                if not isinstance(value, bool):
                    raise TypeError
                return value
            if name in _INTS:
                if isinstance(value, float) and value.is_integer():
                    value = int(value)
                if isinstance(value, bool) or not isinstance(value, int):
                    raise TypeError
                lo, hi = _INTS[name]
                if not lo <= value <= hi:
                    raise MessageFieldError(f"{path}: {value} is out of the {name} range [{lo}, {hi}]")
                return int(value)
        except MessageFieldError:  # a ValueError too: keep its own message (the range)
            raise
        except (TypeError, ValueError):
            raise MessageFieldError(f"{path}: expected a {name}, got {value!r}") from None
        raise MessageFieldError(f"{path}: unsupported field type {name}")
    if isinstance(t, NamespacedType):
        return dict_to_msg(_class(t), value, path)
    raise MessageFieldError(f"{path}: unsupported field type {t!r}")


def dict_to_msg(msg_or_class, data: dict | None, path: str = ""):
    """Fill a message (instance or class) from a dict; returns the message. None = all defaults."""
    msg = msg_or_class() if isinstance(msg_or_class, type) else msg_or_class
    if data is None:
        return msg
    if not isinstance(data, dict):
        raise MessageFieldError(f"{path or type(msg).__name__}: expected a mapping of fields, got {data!r}")
    fields = dict(_fields(msg))
    for key, value in data.items():
        where = f"{path}.{key}" if path else str(key)
        if key not in fields:
            raise MessageFieldError(f"{where}: {type(msg).__name__} has no field {key!r}; its fields: "
                                    f"{', '.join(fields)}")
        t = fields[key]
        try:
            if isinstance(t, AbstractNestedType):
                if not isinstance(value, (list, tuple)):
                    raise MessageFieldError(f"{where}: expected a list, got {value!r}")
                setattr(msg, key, [_scalar(t.value_type, v, f"{where}[{i}]") for i, v in enumerate(value)])
            elif isinstance(t, NamespacedType):
                dict_to_msg(getattr(msg, key), value, where)
            else:
                setattr(msg, key, _scalar(t, value, where))
        except MessageFieldError:
            raise
        except (AssertionError, ValueError, TypeError, OverflowError) as e:  # the generated setters' checks
            raise MessageFieldError(f"{where}: {e or 'value out of range'}") from None
    return msg


def _plain(value):
    if hasattr(value, "get_fields_and_field_types"):
        return msg_to_dict(value)
    if isinstance(value, (list, tuple, array.array, np.ndarray)):
        return [_plain(v) for v in value]
    if isinstance(value, (np.floating, float)):
        return float(value)
    if isinstance(value, (np.integer,)):
        return int(value)
    if isinstance(value, bytes):
        return list(value)
    return value


def msg_to_dict(msg) -> dict:
    """A message as nested dicts and lists of plain Python values (YAML-safe)."""
    return {name: _plain(getattr(msg, name)) for name in msg.get_fields_and_field_types()}

