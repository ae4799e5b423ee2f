"""The solver's settings: the knobs every FMU exposes (added to a model's parameters by the FMI
adapters, never declared by a model), their rules, and the slack that the integration error may
take beyond a domain condition.
"""
from __future__ import annotations

import math
from typing import Mapping, Optional, Tuple

from .. import fmath
from ..model import HybridModel, Parameter, ParameterError, Params, require

SOLVER_PARAMETERS = (
    Parameter("method", 0, "", "integration method: 0 = automatic (Dormand-Prince 5(4), Rodas5P while the "
              "problem is stiff), 5 = Dormand-Prince 5(4) (ode45) only, 8 = DOP853, 1 = Rodas5P (stiff: linearly "
              "implicit, exact Jacobian)", integer=True),
    Parameter("rel_tol", 1e-6, "", "relative error tolerance of the internal solver"),
    Parameter("abs_tol", 1e-12, "", "absolute error tolerance of the internal solver (state units)"),
    Parameter("max_step", 0.01, "s", "largest internal step (0 or inf: unbounded)"),
    Parameter("initial_step", 0.0, "s", "first internal step (0: chosen automatically)"),
    Parameter("log_events", 0, "", "1: report every state event through the FMI logger (category logEvents) "
              "and keep the full event history", integer=True),
    Parameter("max_steps_per_second", 1e5, "1/s", "work budget: most internal steps per second of simulated "
              "time (counted over windows of 1 s); more end the run with an error naming the stiffness"),
    Parameter("max_steps_per_call", 1e6, "", "most internal steps (accepted and rejected) one call may take "
              "(fmi2DoStep, fmi3DoStep): a step that needs more at max_step is refused at once, one that takes "
              "more ends in an error; bounds how long one call blocks its caller"),
)
SOLVER_PARAMETER_NAMES = tuple(par.name for par in SOLVER_PARAMETERS)
REL_TOL_MIN = 1e-14  # tighter ones are below the rounding of a double's state
REL_TOL_MAX = 1e-3  # looser relative tolerances do not control the error (ode45's default)
ABS_TOL_MAX_FRACTION = 1e-3  # abs_tol <= this fraction of the states' scale
METHOD_NAMES = {0: "automatic", 1: "Rodas5P", 5: "DOPRI5", 8: "DOP853"}
DOMAIN_SLACK = 10.0  # a domain condition may be crossed by this many local error tolerances


def solver_parameters() -> Tuple[Parameter, ...]:
    """The solver knobs every FMU exposes after the model's own parameters."""
    return SOLVER_PARAMETERS


def solver_defaults() -> dict:
    return {par.name: par.default for par in SOLVER_PARAMETERS}


def split_parameters(model: HybridModel, values: Mapping, solver: Optional[Mapping] = None) -> Tuple[Params, Params]:
    """``(model parameters, solver settings)`` from one mapping that may hold both (an FMU's
    parameter table); missing model parameters take the model's defaults, missing settings theirs;
    ``solver`` (optional) overrides settings.  A name that is neither is refused."""
    if isinstance(values, Params):
        values = values.as_dict()
    own = model.defaults()
    settings = solver_defaults()
    for name, v in values.items():
        if name in settings:
            settings[name] = v
        elif name in own:
            own[name] = v
        else:
            raise ParameterError(f"unknown parameter {name!r} for model {model.name}")
    for name, v in (solver or {}).items():
        if name not in settings:
            raise ParameterError(f"unknown solver setting {name!r} (one of {', '.join(SOLVER_PARAMETER_NAMES)})")
        settings[name] = v
    return Params(own), Params(settings)


def check_solver_parameters(s: Params, has_states: bool = True):
    """Every rule of the settings, each refusal naming the setting, its value and the rule."""
    for name in SOLVER_PARAMETER_NAMES:
        v = s[name]
        if not fmath.is_number(v):
            raise ParameterError(f"parameter {name} = {v!r} violates the rule: {name} must be a number")
    require(s.method in tuple(METHOD_NAMES), "method", s.method, "method must be 0 (automatic: DOPRI5, Rodas5P "
            "while the problem is stiff), 1 (Rodas5P, stiff), 5 (DOPRI5) or 8 (DOP853)")
    require(REL_TOL_MIN <= s.rel_tol <= REL_TOL_MAX, "rel_tol", s.rel_tol,
            f"{REL_TOL_MIN:g} <= rel_tol <= {REL_TOL_MAX:g} (a looser relative tolerance does not control the error)")
    require(s.abs_tol > 0 and fmath.isfinite(s.abs_tol), "abs_tol", s.abs_tol, "0 < abs_tol < inf")
    require(s.max_step >= 0, "max_step", s.max_step, "max_step >= 0 (0 or inf: unbounded)")
    budget = s.max_steps_per_second
    require(budget >= 10 and budget < math.inf, "max_steps_per_second", budget,
            "10 <= max_steps_per_second < inf")
    # (a model without states takes no internal steps: its max_step is never used)
    require(not has_states or s.max_step == 0 or s.max_step == math.inf or s.max_step * budget >= 2,
            "max_step", s.max_step,
            f"max_step = 0 or max_step >= 2/max_steps_per_second = {2 / budget:.3g} s (a smaller max_step "
            f"alone takes more than half the work budget of {budget:.3g} internal steps per simulated second; "
            f"raise max_steps_per_second to allow it)")
    require(s.max_steps_per_call >= 1 and s.max_steps_per_call < math.inf, "max_steps_per_call",
            s.max_steps_per_call, "1 <= max_steps_per_call < inf")
    require(s.log_events in (0, 1), "log_events", s.log_events, "log_events is 0 or 1")
    require(s.initial_step >= 0 and fmath.isfinite(s.initial_step), "initial_step", s.initial_step,
            "0 <= initial_step < inf (0: automatic)")


def domain_slack(s: Params):
    """``slack(scale)``: how far beyond a domain bound of magnitude ``scale`` a state may lie from
    the integration error alone (DOMAIN_SLACK local tolerances), handed to a model's ``domain``."""
    rtol, atol = s.rel_tol, s.abs_tol

    def slack(scale):
        return DOMAIN_SLACK * (rtol * scale + atol)
    return slack
