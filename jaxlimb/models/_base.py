"""Shared machinery of the sigmoid limb models: named parameter containers.

A parameter container is an :class:`equinox.Module` whose fields are the model's
parameters, in the column order of the Jacobian.  Containers convert to and from
flat vectors (``to_vector`` / ``from_vector``) so that solvers can work on
arrays while users read fields by name.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from dataclasses import fields
from typing import ClassVar, TypeVar

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
from jaxtyping import Array, Float

P = TypeVar("P", bound="LimbParams")


class LimbParams(eqx.Module):
    """Base class of the parameter containers (fields are scalars or batched arrays)."""

    names: ClassVar[tuple[str, ...]] = ()

    @classmethod
    def field_names(cls) -> tuple[str, ...]:
        return tuple(f.name for f in fields(cls))

    def to_vector(self) -> Float[Array, "... p"]:
        """Stack the fields (in Jacobian column order) along a new last axis."""
        vals = [getattr(self, n) for n in self.field_names()]
        if not any(isinstance(v, jax.core.Tracer) for v in vals):  # host values: no program per shape
            return jax.device_put(np.stack([np.asarray(v, dtype=float) for v in vals], axis=-1))
        return jnp.stack([jnp.asarray(v, dtype=float) for v in vals], axis=-1)

    @classmethod
    def from_vector(cls: type[P], v: Float[Array, "... p"]) -> P:
        """Inverse of :meth:`to_vector`."""
        n = len(cls.field_names())
        if isinstance(v, np.ndarray):  # host values: one transfer per field, no program per shape
            return cls(*[jax.device_put(np.array(v[..., i])) for i in range(n)])  # (a copy: 0-d stays 0-d)
        v = jnp.asarray(v)
        return cls(*[v[..., i] for i in range(n)])

    def replace(self: P, **changes: object) -> P:
        """A copy with some fields replaced."""
        vals = {n: getattr(self, n) for n in self.field_names()}
        unknown = set(changes) - set(vals)
        if unknown:
            raise TypeError(f"{type(self).__name__} has no fields {sorted(unknown)}")
        vals.update(changes)
        return type(self)(**vals)

    def as_dict(self) -> dict[str, float]:
        """Plain-Python ``{name: float}`` (scalar containers only)."""
        return {n: float(getattr(self, n)) for n in self.field_names()}


class LimbModel(eqx.Module):
    """A sigmoid limb model: intensity function, analytic Jacobian, parameter type.

    Attributes
    ----------
    name
        Short name (``"linear"``, ``"circle"``, ``"ellipse"``).
    params_type
        The :class:`LimbParams` subclass holding the parameters.
    intensity
        ``intensity(params, coords) -> (n,)`` model intensity at the pixels.
    jacobian
        ``jacobian(params, coords) -> (n, p)``: the paper's analytic derivatives,
        columns in the field order of ``params_type``.
    jacobian_columns
        the same derivatives as a tuple of ``p`` arrays of shape ``(n,)``.
    value_and_columns
        optional ``(intensity, columns)`` from one pass (shares the exponentials; the
        fitting inner loop uses it).
    """

    name: str = eqx.field(static=True)
    params_type: type[LimbParams] = eqx.field(static=True)
    intensity: Callable[..., Array] = eqx.field(static=True)
    jacobian: Callable[..., Array] = eqx.field(static=True)
    jacobian_columns: Callable[..., tuple[Array, ...]] = eqx.field(static=True)
    value_and_columns: Callable[..., tuple[Array, tuple[Array, ...]]] | None = eqx.field(static=True, default=None)

    def intensity_and_jacobian_columns(self, params: LimbParams, coords: Array) -> tuple[Array, tuple[Array, ...]]:
        """Intensity and Jacobian columns, from one fused pass where the model provides it."""
        if self.value_and_columns is not None:
            return self.value_and_columns(params, coords)
        return self.intensity(params, coords), self.jacobian_columns(params, coords)

    def jacobian_t(self, params: LimbParams, coords: Array) -> Array:
        """The analytic Jacobian transposed, ``(p, n)``: the fast layout for ``J^T J`` on CPU."""
        return jnp.stack(self.jacobian_columns(params, coords), axis=0)

    @property
    def param_names(self) -> tuple[str, ...]:
        return self.params_type.field_names()

    def free_indices(self, fixed: Sequence[str] = ()) -> tuple[int, ...]:
        names = self.param_names
        return tuple(i for i, n in enumerate(names) if n not in set(fixed))


def fused_model(name: str, params_type: type[LimbParams], intensity: Callable[..., Array],
                value_and_columns: Callable[..., tuple[Array, tuple[Array, ...]]]) -> LimbModel:
    """A :class:`LimbModel` whose Jacobian columns (and their ``(n, p)`` stack) are those of its one fused pass
    ``value_and_columns(params, coords) -> (intensity, columns)``: the derivative of the function as computed.

    Parameters
    ----------
    name : str
        The model's short name.
    params_type : type
        Its :class:`LimbParams` subclass.
    intensity : callable
        ``intensity(params, coords) -> (n,)`` (the documented public function; ``value_and_columns(...)[0]``).
    value_and_columns : callable
        The fused pass.

    Returns
    -------
    LimbModel
        The model.
    """

    def columns(p: LimbParams, rc: Array) -> tuple[Array, ...]:
        return value_and_columns(p, rc)[1]

    def jacobian(p: LimbParams, rc: Array) -> Array:
        return jnp.stack(value_and_columns(p, rc)[1], axis=-1)

    return LimbModel(name, params_type, intensity, jacobian, columns, value_and_columns)
