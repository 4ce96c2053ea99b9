"""The method registry: what each method builds, where its context comes from, what trains it.

One entry per method. The agent, the representation losses, config validation, the CLI choices
and the report order all read this table, so a new baseline (or a variant of one) is one entry
here plus, if it needs a new objective, one branch in representation.py.
"""

from __future__ import annotations

from dataclasses import dataclass

__all__ = ['METHODS', 'METHOD_REGISTRY', 'MethodSpec', 'method_spec']


@dataclass(frozen=True)
class MethodSpec:
    """How one method conditions its policy and learns its context."""

    name: str
    context_source: str
    """'psi' (learned encoder psi(H)), 'true' (the true context, privileged) or 'none'."""
    models: tuple[str, ...]
    """Auxiliary models trained on the context: 'transition', 'reward', 'backward'."""
    objective: str
    """Representation objective: 'zeus' (dynamics + reward, eq. 1 when alpha_psi > 0), 'cadm'
    (forward + backward dynamics), 'up_osi' (regression on the true context) or 'none'."""
    context_loss: bool
    """Whether eq. 1's context loss applies (needs a pair batch)."""
    description: str


METHOD_REGISTRY: dict[str, MethodSpec] = {spec.name: spec for spec in (
    MethodSpec('zeus', 'psi', ('transition', 'reward'), 'zeus', True,
               'ZeUS: psi(H) trained by dynamics + reward prediction and the context loss'),
    MethodSpec('zeus_no_context_loss', 'psi', ('transition', 'reward'), 'zeus', False,
               'ZeUS ablation: alpha_psi = 0 (dynamics + reward only)'),
    MethodSpec('no_context', 'none', (), 'none', False,
               'SAC(-AE) on the observation alone'),
    MethodSpec('up_osi', 'psi', (), 'up_osi', False,
               'UP-OSI: psi(H) regressed on the true context (privileged in training)'),
    MethodSpec('cadm', 'psi', ('transition', 'backward'), 'cadm', False,
               'CaDM: psi(H) trained by forward + backward dynamics'),
    MethodSpec('oracle', 'true', ('transition', 'reward'), 'zeus', False,
               'upper bound: ZeUS architecture and auxiliary losses, psi replaced by the true '
               'context (normalised like every context)'),
    MethodSpec('oracle_sac', 'true', (), 'none', False,
               'plain SAC on the observation and the true context'),
)}
"""Every method, in the order tables list them."""

METHODS = tuple(METHOD_REGISTRY)
"""Method names, in table order."""


def method_spec(name: str) -> MethodSpec:
    """The registry entry of `name` (ValueError listing the methods when unknown)."""
    try:
        return METHOD_REGISTRY[name]
    except KeyError:
        raise ValueError(f'unknown method {name!r}; methods: {", ".join(METHODS)}') from None
