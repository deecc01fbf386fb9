"""Property overrides: ``--set PATH=VALUE`` sets one RNA property of the scene before rendering.

Syntax::

    OVERRIDE := PATH "=" VALUE
    PATH     := STEP ("." STEP)*
    STEP     := NAME ("[" KEY "]")*
    NAME     := a letter, then letters, digits, "_"
    KEY      := "quoted name" | 'quoted name' | integer index      (backslash escapes a quote or a backslash)
    VALUE    := ITEM ("," ITEM)*                                     (spaces around items are ignored)

Examples::

    cycles.sample_clamp_indirect=0
    render.resolution_x=128
    view_layers["ViewLayer"].cycles.use_denoising=false
    objects["Light"].data.energy=100
    lights["Light"].energy=100
    materials["Walls"].node_tree.nodes["Diffuse BSDF"].inputs["Color"].default_value=0.21,0.21,0.21,1
    world.node_tree.nodes["Background"].inputs["Color"].default_value=0.1,0.1,0.1,1

(``world.color`` is the viewport colour only: Blender 5.0 worlds always render through their nodes.)

A first step named ``objects``, ``materials``, ``lights``, ``worlds``, ``cameras``, ``meshes``, ``node_groups``,
``images`` or ``textures`` is looked up in ``bpy.data``; any other first step is a property of the scene
(``world.`` is the scene's world; a leading ``scene.`` is allowed). Each step must be an RNA property of the
struct before it (no Python attributes, no methods, nothing is evaluated). The last step must be a boolean,
integer, float, enum or string property that is not read-only. Values: booleans ``true``/``false``/``1``/``0``
(any case); integers; finite floats inside the property's hard range; enum identifiers (flag enums take several
items); arrays take exactly one item per element; strings take the whole value (quote it to keep spaces).

`parse_override` needs no Blender; `apply_overrides` resolves, validates all overrides, then applies them.
"""

from __future__ import annotations

import difflib
import json
import math
import re
from collections.abc import Iterable
from dataclasses import dataclass

from ..errors import BatchError
from .rna import jsonable

DATA_COLLECTIONS = frozenset(
    {"objects", "materials", "lights", "worlds", "cameras", "meshes", "node_groups", "images", "textures"}
)

_NAME = re.compile(r"[A-Za-z][A-Za-z0-9_]*")
_INDEX = re.compile(r"-?[0-9]+")
_INT_VALUE = re.compile(r"[+-]?[0-9]+")
_TRUE, _FALSE = frozenset({"true", "1"}), frozenset({"false", "0"})


class OverrideError(BatchError, ValueError):
    """An override that cannot be parsed, resolved, validated or applied; the message is one line, `reason` that
    line without the override it is about."""

    def __init__(self, text: str, reason: str):
        super().__init__(f"--set {text}: {reason}")
        self.reason = reason


@dataclass(frozen=True)
class Step:
    """One step of a path: a property name and the collection keys that follow it."""

    name: str
    keys: tuple[str | int, ...] = ()

    def __str__(self) -> str:
        return self.name + "".join(f"[{json.dumps(k)}]" for k in self.keys)


@dataclass(frozen=True)
class Override:
    """A parsed ``PATH=VALUE``: `text` as given, the path's `steps`, the raw `value` and its unquoted `items`."""

    text: str
    steps: tuple[Step, ...]
    value: str
    items: tuple[str, ...]

    @property
    def path(self) -> str:
        """The path in canonical form (keys in double quotes)."""
        return ".".join(str(s) for s in self.steps)


def _error(text: str, reason: str) -> OverrideError:
    return OverrideError(text, reason)


# ---------------------------------------------------------------------------------------------------------------
# Parsing (pure Python)


def parse_override(text: str) -> Override:
    """Parse ``PATH=VALUE`` (see the module docstring) without touching Blender.

    Raises
    ------
    OverrideError
        The text does not follow the syntax; the message says where.
    """
    steps: list[Step] = []
    pos = 0
    while True:
        match = _NAME.match(text, pos)
        if match is None:
            raise _malformed(text, pos, "expected a property name")
        pos = match.end()
        keys: list[str | int] = []
        while pos < len(text) and text[pos] == "[":
            key, pos = _parse_key(text, pos + 1)
            keys.append(key)
        steps.append(Step(match.group(), tuple(keys)))
        if pos < len(text) and text[pos] == ".":
            pos += 1
            continue
        break
    while pos < len(text) and text[pos] == " ":
        pos += 1
    if pos >= len(text) or text[pos] != "=":
        raise _malformed(text, pos, "expected '=' after the path")
    value = text[pos + 1 :].strip()
    if not value:
        raise _error(text, "no value after '='")
    return Override(text, tuple(steps), value, _split_items(text, value))


def _malformed(text: str, pos: int, reason: str) -> OverrideError:
    where = f"at character {pos + 1}" if pos < len(text) else "at the end"
    return _error(text, f"malformed override {where}: {reason} (syntax: PATH=VALUE, e.g. cycles.samples=16)")


def _parse_key(text: str, pos: int) -> tuple[str | int, int]:
    """A key after '[': a quoted name or an integer; returns it and the position after ']'."""
    if pos < len(text) and text[pos] in "\"'":
        key, pos = _parse_quoted(text, pos)
    else:
        match = _INDEX.match(text, pos)
        if match is None:
            raise _malformed(text, pos, "expected a quoted name or an integer inside [ ]")
        key, pos = int(match.group()), match.end()
    if pos >= len(text) or text[pos] != "]":
        raise _malformed(text, pos, "expected ']'")
    return key, pos + 1


def _parse_quoted(text: str, pos: int) -> tuple[str, int]:
    """A string in quotes starting at `pos`; returns its content and the position after the closing quote."""
    quote, chars, i = text[pos], [], pos + 1
    while i < len(text):
        char = text[i]
        if char == "\\" and i + 1 < len(text):
            chars.append(text[i + 1])
            i += 2
        elif char == quote:
            return "".join(chars), i + 1
        else:
            chars.append(char)
            i += 1
    raise _malformed(text, pos, "unterminated quote")


def _split_items(text: str, value: str) -> tuple[str, ...]:
    """Split a value at commas outside quotes; quoted items are unquoted."""
    items, pos = [], 0
    while True:
        while pos < len(value) and value[pos] == " ":
            pos += 1
        if pos < len(value) and value[pos] in "\"'":
            item, pos = _parse_quoted(value, pos)
            while pos < len(value) and value[pos] == " ":
                pos += 1
        else:
            end = value.find(",", pos)
            end = len(value) if end < 0 else end
            item = value[pos:end].strip()
            if not item:
                raise _error(text, "empty item in the value")
            pos = end
        items.append(item)
        if pos >= len(value):
            return tuple(items)
        if value[pos] != ",":
            raise _error(text, "expected ',' between items of the value")
        pos += 1


# ---------------------------------------------------------------------------------------------------------------
# Resolution, validation and application (bpy)


@dataclass(frozen=True)
class _Target:
    override: Override
    struct: object  # the bpy_struct that owns the property
    name: str
    label: str  # 'Struct.property' for messages
    value: object


def apply_overrides(scene, overrides: Iterable[Override | str]) -> list[dict]:
    """Resolve and validate every override, then apply them to `scene` in order.

    Parameters
    ----------
    scene : bpy.types.Scene
    overrides : iterable of Override or str
        Parsed overrides or their text.

    Returns
    -------
    list of dict
        One ``{"override", "path", "old", "new"}`` per override, with JSON-able values.

    Raises
    ------
    OverrideError
        The first override that does not resolve or validate; nothing has been changed then.
    """
    targets = [_resolve(scene, o if isinstance(o, Override) else parse_override(o)) for o in overrides]
    changes = []
    for target in targets:
        old = jsonable(getattr(target.struct, target.name))
        try:
            setattr(target.struct, target.name, target.value)
        except (TypeError, ValueError, AttributeError) as error:
            reason = str(error).strip().splitlines()[-1]
            raise _error(target.override.text, f"Blender refused the value: {reason}") from None
        new = jsonable(getattr(target.struct, target.name))
        if isinstance(target.value, str) and new != target.value:  # truncated or renamed: not what was asked
            raise _error(target.override.text, f"Blender stored {new!r} instead ('{target.label}' holds at most "
                                               f"{len(new)} characters, or changes some)")  # fmt: skip
        changes.append({"override": target.override.text, "path": target.override.path, "old": old, "new": new})
    if targets:
        # Python-defined settings (scene.cycles.*) do not tag the depsgraph by themselves.
        scene.update_tag()
    return changes


def _resolve(scene, override: Override) -> _Target:
    import bpy

    text, steps = override.text, override.steps
    if len(steps) > 1 and steps[0] == Step("scene"):
        steps = steps[1:]  # 'scene.cycles.samples' means 'cycles.samples'
    first = steps[0]
    current = bpy.data if first.name in DATA_COLLECTIONS and first.keys else scene
    for index, step in enumerate(steps):
        last = index == len(steps) - 1
        if last and step.keys:
            raise _error(text, f"the path must end with a property name, not with a key ({step})")
        prop = _property(text, current, step.name)
        if last:
            return _validated(override, current, prop)
        label = f"{_struct_name(current)}.{step.name}"
        current = getattr(current, step.name)
        for key in step.keys:
            current = _lookup(text, current, key, label)
            label = f"{label}[{json.dumps(key)}]"
        if current is None:
            raise _error(text, f"'{label}' is not set (None)")
    raise AssertionError("unreachable: a parsed path has at least one step")


def _struct_name(struct) -> str:
    return struct.bl_rna.identifier


def _property(text: str, struct, name: str):
    """The RNA property `name` of `struct`, or a clear error naming the struct (and a close match)."""
    props = struct.bl_rna.properties
    prop = props.get(name)
    if prop is None or name == "rna_type":
        hint = difflib.get_close_matches(name, [p for p in props.keys() if p != "rna_type"], n=1)
        suffix = f" (did you mean '{hint[0]}'?)" if hint else ""
        raise _error(text, f"'{_struct_name(struct)}' has no property '{name}'{suffix}")
    return prop


def _lookup(text: str, collection, key: str | int, label: str):
    import bpy

    if not isinstance(collection, bpy.types.bpy_prop_collection):
        raise _error(text, f"'{label}' is not a collection, it cannot take [{json.dumps(key)}]")
    if isinstance(key, int):
        if -len(collection) <= key < len(collection):
            return collection[key]
        raise _error(text, f"index {key} is out of range for '{label}' ({len(collection)} items)")
    item = collection.get(key)
    if item is None:
        names = [getattr(i, "name", "") for i in collection]
        shown = ", ".join(json.dumps(n) for n in names[:12]) + (", ..." if len(names) > 12 else "")
        raise _error(text, f"no {json.dumps(key)} in '{label}' (has: {shown or 'nothing'})")
    return item


def _validated(override: Override, struct, prop) -> _Target:
    text = override.text
    label = f"{_struct_name(struct)}.{prop.identifier}"
    if prop.is_readonly:
        raise _error(text, f"'{label}' is read-only")
    kind = prop.type
    if kind == "STRING":
        value = override.items[0] if len(override.items) == 1 else override.value
        return _Target(override, struct, prop.identifier, label, value)
    if kind == "ENUM":
        return _Target(override, struct, prop.identifier, label, _enum_value(override, prop, label))
    if kind not in ("BOOLEAN", "INT", "FLOAT"):
        raise _error(
            text, f"'{label}' is a {kind.lower()} property; only booleans, numbers, enums and strings can be set"
        )
    dims = [d for d in prop.array_dimensions if d] if prop.array_length else []
    if len(dims) > 1:
        raise _error(text, f"'{label}' is a {'×'.join(map(str, dims))} array; only vectors can be set")
    length = prop.array_length
    items = override.items
    if length == 0 and len(items) != 1:
        raise _error(text, f"'{label}' takes one value, got {len(items)}")
    if length and len(items) != length:
        raise _error(text, f"'{label}' takes {length} comma-separated values, got {len(items)}")
    values = [_scalar(text, prop, label, item) for item in items]
    return _Target(override, struct, prop.identifier, label, values[0] if length == 0 else values)


def _scalar(text: str, prop, label: str, item: str):
    """One boolean, integer or float item, checked against the property's hard range."""
    if prop.type == "BOOLEAN":
        word = item.lower()
        if word in _TRUE | _FALSE:
            return word in _TRUE
        raise _error(text, f"'{label}' expects true/false/1/0, got '{item}'")
    if prop.type == "INT":
        if not _INT_VALUE.fullmatch(item):
            raise _error(text, f"'{label}' expects an integer, got '{item}'")
        number = int(item)
    else:
        try:
            number = float(item)
        except ValueError:
            raise _error(text, f"'{label}' expects a number, got '{item}'") from None
        if not math.isfinite(number):
            raise _error(text, f"'{label}' expects a finite number, got '{item}'")
    if not prop.hard_min <= number <= prop.hard_max:
        low, high = (f"{x}" if prop.type == "INT" else f"{x:g}" for x in (prop.hard_min, prop.hard_max))
        raise _error(text, f"{item} is outside the range of '{label}' [{low}, {high}]")
    return number


def _enum_value(override: Override, prop, label: str):
    identifiers = [item.identifier for item in prop.enum_items]
    items = override.items
    if not prop.is_enum_flag and len(items) != 1:
        raise _error(override.text, f"'{label}' takes one identifier, got {len(items)}")
    # Enums filled at run time list no items here; Blender checks those when the value is set.
    bad = [item for item in items if identifiers and item not in identifiers]
    if bad:
        choices = ", ".join(f"'{i}'" for i in identifiers)
        raise _error(override.text, f"'{bad[0]}' is not a value of '{label}' (choose from {choices})")
    return set(items) if prop.is_enum_flag else items[0]
