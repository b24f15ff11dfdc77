"""Validate a YAML section with a pydantic model and report the first problem as one line."""

from __future__ import annotations

import types
import typing
from typing import TypeVar, Union

from pydantic import BaseModel, ValidationError

from nlcx.errors import MISSING, ConfigError, did_you_mean

M = TypeVar("M", bound=BaseModel)


def validate_model(model: type[M], data: object, path: str) -> M:
    """``model.model_validate(data)``; a :class:`ConfigError` under ``path`` if invalid."""
    if data is None:
        data = {}
    if not isinstance(data, dict):
        raise ConfigError(path, data, "must be a mapping of keys to values")
    try:
        return model.model_validate(data)
    except ValidationError as exc:
        raise config_error(model, exc, path) from None


def join(path: str, *parts: object) -> str:
    """Dotted key path."""
    return ".".join([p for p in (path, *map(str, parts)) if p])


def config_error(model: type[BaseModel], exc: ValidationError, path: str) -> ConfigError:
    """The first pydantic error as a ConfigError naming key path, value and what is allowed."""
    err = exc.errors()[0]
    loc = tuple(err["loc"])
    where = join(path, *loc)
    kind = err["type"]
    value = err.get("input", MISSING)
    if kind == "extra_forbidden":
        allowed_keys = _allowed_keys(model, loc[:-1])
        message = f"unknown key; allowed keys: {', '.join(allowed_keys)}{did_you_mean(str(loc[-1]), allowed_keys)}"
        return ConfigError(where, value, message)
    if kind == "missing":
        return ConfigError(where, MISSING, "required key is missing")
    if kind == "literal_error":
        expected = err.get("ctx", {}).get("expected", "")
        return ConfigError(where, value, f"allowed values: {expected}")
    message = str(err["msg"])
    message = message.removeprefix("Value error, ").removeprefix("Assertion failed, ")
    message = message.replace("Input should be", "must be")
    return ConfigError(where, value, message)


def _unwrap(annotation: object) -> list[object]:
    origin = typing.get_origin(annotation)
    if origin in (Union, types.UnionType):
        out: list[object] = []
        for arg in typing.get_args(annotation):
            out.extend(_unwrap(arg))
        return out
    if origin is typing.Annotated:
        return _unwrap(typing.get_args(annotation)[0])
    return [annotation]


def _allowed_keys(model: type[BaseModel], loc: tuple[int | str, ...]) -> list[str]:
    """Field names of the (sub-)model found by following ``loc`` through the annotations."""
    current: object = model
    for part in loc:
        nxt = None
        for candidate in _unwrap(current):
            if isinstance(candidate, type) and issubclass(candidate, BaseModel):
                field = candidate.model_fields.get(str(part))
                if field is not None:
                    nxt = field.annotation
                    break
            elif typing.get_origin(candidate) is dict:
                nxt = typing.get_args(candidate)[1]
                break
        if nxt is None:
            return []
        current = nxt
    for candidate in _unwrap(current):
        if isinstance(candidate, type) and issubclass(candidate, BaseModel):
            return sorted(candidate.model_fields)
    return []
