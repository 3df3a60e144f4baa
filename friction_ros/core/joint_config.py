"""Per-joint configuration of the multi-joint nodes, in the layout ros2_controllers users know.

A node that handles several joints (``joints: [j1, j2, ...]``) takes node-level values as the
defaults of every joint and per-joint values on top:

* ``<section>.<joint>.<key>``: a key of a section for one joint (``friction.j3.model``,
  ``friction.j3.fc``, ``compensation.j3.gain``, ``load.j3.gravity``, ``pid.j3.p``,
  ``reference.j3.amplitude`` ...), as ros2_controllers' ``constraints.<joint>.goal``;
* ``gains.<joint>.<key>``: ros2_controllers' ``pid_controller`` layout: the PID keys
  (``gains.j3.p``, ``.i``, ``.d``, ``.i_clamp_max`` ...) and the node's plain per-joint settings
  (``gains.j3.u_clamp_max``, ``gains.j3.feedforward_gain``, ``gains.j3.inertia`` ...).

A per-joint section that names its own ``model`` (``friction.j3.model``) replaces the node-level
section of that joint as a whole (another model has other coefficients); otherwise per-joint keys
are laid over the node-level ones. Pure functions: the ROS declaration is
``friction_ros.nodes.joint_parameters``.
"""

from __future__ import annotations

import copy
import re
from collections.abc import Iterable, Iterator, Mapping
from contextlib import contextmanager
from typing import Any

from friction_ros.core.config import Names, unflatten
from friction_ros.core.validation import ParameterError

JOINT_NAME = re.compile(r"^[A-Za-z][A-Za-z0-9_]*$")
GAINS = "gains"
#: section -> the key whose per-joint value replaces the node-level section as a whole
REPLACED_BY = {"friction": "model", "reference": "type"}


def check_joint_list(joints: Iterable[str], reserved: Iterable[str] = ()) -> list[str]:
    """Joint names usable in parameter names: letters, digits, '_'; none twice, none a parameter key."""
    joints = list(joints)
    reserved = set(reserved)
    for i, j in enumerate(joints):
        if not isinstance(j, str) or not JOINT_NAME.match(j):
            raise ParameterError(
                f"joints[{i}] = {j!r} is not allowed: must start with a letter and hold only letters, "
                "digits and '_' (it names per-joint parameters, e.g. gains.<joint>.p)"
            )
        if j in reserved:
            raise ParameterError(
                f"joints[{i}] = {j!r} clashes with the parameter key '{j}': rename the joint"
            )
        if j in joints[:i]:
            raise ParameterError(f"joints[{i}] = {j!r} appears twice: joint names must differ")
    return joints


class JointLayout:
    """Which parameter names are per-joint, and the node-level name each one stands for.

    ``sections``: the node's section names (``pid``, ``friction`` ...); ``gains_keys`` /
    ``plain_keys``: the keys ``gains.<joint>.<key>`` accepts, mapped to ``<gains_section>.<key>``
    and ``<key>`` respectively.
    """

    def __init__(
        self,
        joints: Iterable[str],
        sections: Iterable[str],
        gains_section: str | None = None,
        gains_keys: Iterable[str] = (),
        plain_keys: Iterable[str] = (),
    ):
        self.joints = list(joints)
        self._joint_set = set(self.joints)
        self.sections = set(sections)
        self.gains_section = gains_section
        self.gains_keys = set(gains_keys)
        self.plain_keys = set(plain_keys)

    def split(self, name: str) -> tuple[str, str] | None:
        """``(joint, node-level name)`` of a per-joint parameter name; None for a node-level one.

        ``gains.<joint>.<key>`` with a key that is neither a PID key nor a per-joint setting raises
        :class:`ParameterError` naming the allowed keys.
        """
        parts = name.split(".")
        if len(parts) < 3 or parts[1] not in self._joint_set:
            return None
        section, joint, rest = parts[0], parts[1], ".".join(parts[2:])
        if section == GAINS and (self.gains_keys or self.plain_keys):
            if rest in self.gains_keys:
                return joint, f"{self.gains_section}.{rest}"
            if rest in self.plain_keys:
                return joint, rest
            allowed = ", ".join(sorted(self.gains_keys | self.plain_keys))
            raise ParameterError(f"{name}: {rest!r} is not a per-joint gain; allowed keys: {allowed}")
        if section in self.sections:
            return joint, f"{section}.{rest}"
        return None

    def joint_name(self, joint: str, base: str) -> str:
        """The per-joint parameter name of node-level ``base`` (inverse of :meth:`split`)."""
        head, _, rest = base.partition(".")
        if not rest:
            return f"{GAINS}.{joint}.{base}"
        if head == self.gains_section:
            return f"{GAINS}.{joint}.{rest}"
        return f"{head}.{joint}.{rest}"

    def split_all(self, flat: Mapping[str, Any]) -> tuple[dict[str, Any], dict[str, dict[str, Any]]]:
        """Flat values -> (node-level flat values, {joint: {node-level name: value}})."""
        node: dict[str, Any] = {}
        per_joint: dict[str, dict[str, Any]] = {j: {} for j in self.joints}
        for k, v in flat.items():
            hit = self.split(k)
            if hit is None:
                node[k] = v
            else:
                per_joint[hit[0]][hit[1]] = v
        return node, per_joint


def joint_values(
    node_values: Mapping[str, Any], overrides: Mapping[str, Any], replaced_by: Mapping[str, str] | None = None
) -> dict[str, Any]:
    """One joint's nested values: ``node_values`` with the joint's ``overrides`` (node-level flat
    names) on top. ``replaced_by`` (section -> key, default friction: model, reference: type): a section
    whose override names that key replaces the node-level section as a whole."""
    replaced_by = REPLACED_BY if replaced_by is None else replaced_by
    out = copy.deepcopy(dict(node_values))
    nested = unflatten(overrides)
    for key, value in nested.items():
        if isinstance(value, dict) and isinstance(out.get(key), dict):
            if key in replaced_by and replaced_by[key] in value:
                out[key] = copy.deepcopy(value)
            else:
                _merge(out[key], value)
        else:
            out[key] = copy.deepcopy(value)
    return out


def _merge(base: dict, top: Mapping) -> None:
    for k, v in top.items():
        if isinstance(v, Mapping) and isinstance(base.get(k), dict):
            _merge(base[k], v)
        else:
            base[k] = copy.deepcopy(v)


class JointNames:
    """The parameter names of one joint's effective values, as the user wrote them (a
    :data:`~friction_ros.core.config.Names`): ``names("plant.gravity")`` is the per-joint name
    ``plant.j2.gravity`` when the joint has its own value (``overridden``: its node-level flat names),
    or a key of a section the joint replaces as a whole (``replaced_by`` as in :func:`joint_values`),
    else the node-level name ``plant.gravity`` (the value every joint shares); a section with any key
    of the joint's own by its per-joint name (``friction.j2``, ``gains.j2``). Core objects take it
    where they take a name prefix, so their messages need no renaming.
    """

    def __init__(
        self,
        layout: JointLayout,
        joint: str,
        overridden: Iterable[str] = (),
        replaced_by: Mapping[str, str] | None = None,
    ):
        self.layout, self.joint = layout, joint
        self.own = frozenset(overridden)
        replaced_by = REPLACED_BY if replaced_by is None else replaced_by
        self.replaced = frozenset(s for s, k in replaced_by.items() if f"{s}.{k}" in self.own)

    def __call__(self, rel: str) -> str:
        head, _, rest = rel.partition(".")
        if rel in self.own or (rest and head in self.replaced):
            return self.layout.joint_name(self.joint, rel)
        if rel and (rel in self.replaced or any(k.startswith(f"{rel}.") for k in self.own)):
            return self.layout.joint_name(self.joint, f"{rel}._").removesuffix("._")  # a section
        return rel

    def owns(self, name: str | None) -> bool:
        """Whether ``name`` (``plant.j2.gravity``, ``presliding.j2.amplitudes[0]``) is one of this
        joint's own per-joint parameters (joint names clash with no parameter key)."""
        parts = (name or "").split("[", 1)[0].split(".")
        return len(parts) >= 2 and parts[1] == self.joint

    def __deepcopy__(self, memo: dict) -> JointNames:  # immutable
        return self


@contextmanager
def joint_errors(names: Names | None) -> Iterator[None]:
    """Build one joint's objects: a :class:`ParameterError` about one of the joint's own parameters
    (named by ``names``) passes as it is; one about a shared node-level value, or a rule across
    values, says which joint's effective config it is (``joint j2: plant.gear_ratio = -2 ...``).
    Names that are no :class:`JointNames` (a single-joint node) let every error pass."""
    try:
        yield
    except ParameterError as exc:
        if not isinstance(names, JointNames) or names.owns(exc.parameter):
            raise
        raise ParameterError(f"joint {names.joint}: {exc}", exc.parameter) from None
