"""Griffe extensions for visjax's API reference (loaded by mkdocstrings, see mkdocs.yml).

- `PublicReexports`: `from ._module import name as name` marks `name` public. visjax
  re-exports each public name from its package this way (the equinox convention) and
  defines no `__all__`; griffe otherwise treats every imported name as private. This is
  what the `griffe-public-redundant-alias` package does, kept here to add no dependency.
- `JaxtypingShapes`: griffe reads a string inside a subscript as a forward reference, so
  the shape of `Float[Array, "6"]` would be shown as the number `6`; this keeps every
  jaxtyping shape a string, as written.
"""

import ast
import dataclasses

import griffe

_JAXTYPING = {
    "Float",
    "Int",
    "UInt",
    "Integer",
    "Bool",
    "Complex",
    "Inexact",
    "Real",
    "Num",
    "Shaped",
    "Key",
}


class PublicReexports(griffe.Extension):
    def on_alias_instance(self, *, node, alias, agent, **kwargs):
        if isinstance(node, ast.ImportFrom):
            for name in node.names:
                if name.asname is not None and name.asname == name.name == alias.name:
                    alias.public = True


def _quote_shapes(expr):
    """Quote the shape of every jaxtyping subscript in an expression, in place."""
    if not dataclasses.is_dataclass(expr):
        return
    if isinstance(expr, griffe.ExprSubscript) and isinstance(expr.slice, griffe.ExprTuple):
        left = expr.left
        name = getattr(left, "name", None)
        elements = expr.slice.elements
        if name in _JAXTYPING and len(elements) == 2:
            shape = elements[1]
            if not (isinstance(shape, str) and shape.startswith(("'", '"'))):
                elements[1] = repr(str(shape))  # "6" read as 6, "N" as a name
    for field in dataclasses.fields(expr):
        value = getattr(expr, field.name)
        for item in value if isinstance(value, list) else [value]:
            _quote_shapes(item)


def _objects(obj):
    yield obj
    for member in obj.members.values():
        if not member.is_alias:
            yield from _objects(member)


class JaxtypingShapes(griffe.Extension):
    def on_package(self, *, pkg, **kwargs):
        for obj in _objects(pkg):
            if obj.is_function:
                for parameter in obj.parameters:
                    _quote_shapes(parameter.annotation)
                _quote_shapes(obj.returns)
            elif obj.is_attribute:
                _quote_shapes(obj.annotation)
