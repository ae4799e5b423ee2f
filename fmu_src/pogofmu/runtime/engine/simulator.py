"""The hybrid engine: embedded Runge-Kutta integration with exact state-event location.

One :class:`Simulator` integrates any :class:`~pogofmu.runtime.model.HybridModel`:

* Dormand-Prince 5(4) (``method=5``, the pair behind ode45) or 8(5,3) (``method=8``, DOP853),
  with the usual error control (``rel_tol``, ``abs_tol``, ``max_step``, ``initial_step``);
* after every accepted step the active guards are evaluated; a sign change in the guard's
  direction is located on the step's continuous extension (dense output) by a safeguarded
  Illinois iteration to a time tolerance of a few ulps of ``t``; the step is then redone exactly
  up to the event (so the state at the event has the full order of the method, not the order of
  the interpolant) and a few secant iterations on such exact steps land that state on the guard;
  the jump is applied and integration restarts there;
* the integrator runs *ahead* of the communication points and serves them from the dense output:
  the step sequence, and so every event time, does not depend on the communication grid.  Only a
  change of input forces a restart at the communication point;
* an event storm (more than ``zeno_max_events`` events within ``zeno_window`` seconds) and a step
  size that collapses end in a :class:`~pogofmu.runtime.model.ZenoError` / error, never in a hang;
* a work budget (parameter ``max_steps_per_second``, windows of 1 s of simulated time) ends a
  run that turns stiff with an error naming the model's fastest time scales, after a warning at
  20 % of it; a model without states takes no internal steps at all;
* the event bookkeeping is of constant size (count, last event, times of the latest events); the
  full history only with ``log_events = 1`` (or ``keep_history=True``).

Restart rule (no re-detection of the event just handled): a guard only fires when its value at
the start of a step lies strictly on the "before" side (``> 0`` for a falling guard, ``< 0`` for a
rising one); a guard that is exactly zero after a jump is disarmed until it leaves zero.  At the
start of the simulation a guard exactly at zero whose motion leaves it towards its "after" side
fires at the start time (a stick at its free length moving up lifts off at t0).
"""
from __future__ import annotations
from __future__ import annotations

import math
from collections import deque
from dataclasses import dataclass
from typing import List, Optional

from .. import fmath
from ..model import DomainError, HybridModel, ModelError, ParameterError, ZenoError, FALLING
from .pairs import METHODS
from .settings import ABS_TOL_MAX_FRACTION, check_solver_parameters, domain_slack, split_parameters

EPS = 2.220446049250313e-16
SAFETY = 0.9
MIN_FACTOR = 0.2
MAX_FACTOR = 10.0
MIN_STEP_ULPS = 10  # a step of at most this many ulps of max(|t|, 1) has collapsed
START_STEP_ULPS = 100  # the automatic first step is never smaller than this (Hairer's estimate can be:
#                        tight abs_tol on a state that starts at 0 with a nonzero rate, issue 9 item 3)
BUDGET_WINDOW = 1.0  # s of simulated time over which max_steps_per_second is counted
BUDGET_WARN_FRACTION = 0.2  # warn when a window has used this fraction of its budget
MIN_TIME_SCALE = 1e-9  # s: faster physical time scales are refused at initialization
UNBOUNDED_STEP_FACTOR = 10.0  # max_step = 0: steps still <= this x max(|t|, 1) s (an exactly integrated
#                               parabola, err = 0, grew the step tenfold per step to 1e151 s, issue 9)
STORM_EVENTS = 5  # a collapsed step after an event is an event storm if this many events lie in zeno_window


def _rms(v):
    return math.sqrt(sum(a * a for a in v) / len(v)) if len(v) else 0.0


# =============================================================================================
# Simulator
# =============================================================================================

@dataclass
class EventRecord:
    """One handled event: when, which, and the state just before and after its jump."""

    time: float
    name: str
    index: int
    x_before: list
    x_after: list


class _Segment:
    """One accepted step ``[t0, t1]`` in one discrete state, with lazily built dense output."""

    __slots__ = ("t0", "t1", "y0", "y1", "f0", "K", "fun", "pair", "_dense")

    def __init__(self, t0, t1, y0, y1, f0, K, fun, pair):
        self.t0, self.t1, self.y0, self.y1, self.f0 = t0, t1, y0, y1, f0
        self.K, self.fun, self.pair = K, fun, pair
        self._dense = None

    def __call__(self, t):
        if t == self.t1:
            return self.y1
        if t == self.t0:
            return self.y0
        return (self._dense or self.dense())(t)

    def dense(self):
        """The step's continuous extension (built on first use)."""
        if self._dense is None:
            self._dense = self.pair.dense(self.fun, self.t0, self.y0, self.y1, self.t1 - self.t0, self.K)
        return self._dense



class Simulator:
    """Integrates one :class:`HybridModel` from ``t0`` on; see the module docstring.

    ``p`` holds the model's parameters (missing ones take their defaults) and may hold solver
    settings too (an FMU's parameter table holds both); ``solver`` overrides settings
    (:mod:`.settings`).  ``self.p`` is the model's own parameters, the only ones its functions see;
    ``self.solver`` the settings.

    Event bookkeeping in constant memory: ``n_events``, ``last_event`` (an :class:`EventRecord`
    or None) and the times of the latest ``zeno_max_events`` events (for the event-storm bound).
    The full history ``events`` is kept only with ``keep_history`` (default: the setting
    ``log_events = 1``); then ``new_events`` also collects the events a caller has not taken yet
    (the FMI adapter logs and clears them after every call).  ``new_warnings`` collects warning
    texts (the work budget) the same way.
    """

    def __init__(self, model: HybridModel, p=None, u=None, t0: float = 0.0, t_stop: float = math.inf,
                 zeno_max_events: int = 200, zeno_window: float = 1e-6, keep_history: Optional[bool] = None,
                 solver=None):
        p, s = split_parameters(model, {} if p is None else p, solver)
        self.model = model
        self.p = p
        self.solver = s
        self.u = tuple(float(v.start) for v in model.inputs) if u is None else tuple(u)
        try:  # every rule first, in the order of prepare(), before any setting is used
            x, q = prepare(model, p, s, self.u)
        except (ArithmeticError, ValueError) as exc:
            if isinstance(exc, ModelError):
                raise
            raise self._arithmetic_error(exc, "initialization") from None
        self.pair = METHODS[int(s.method)]
        self.rtol = float(s.rel_tol)
        self.atol = float(s.abs_tol)
        self._slack = domain_slack(s)
        ms = float(s.max_step)
        self.max_step = math.inf if ms == 0.0 else ms
        self.t_stop = float(t_stop)
        self.zeno_max_events = zeno_max_events
        self.zeno_window = zeno_window
        self.t = float(t0)  # integrator time (may be ahead of the communication time)
        self.t_out = float(t0)  # latest time served to the caller
        self.n_events = 0
        self.last_event: Optional[EventRecord] = None
        keep = bool(s.log_events) if keep_history is None else bool(keep_history)
        self._history: Optional[List[EventRecord]] = [] if keep else None
        self.new_events: List[EventRecord] = []  # filled only when the history is kept
        self.new_warnings: List[str] = []
        self._recent = deque(maxlen=max(zeno_max_events, STORM_EVENTS))  # (time, name) of the latest events
        self.seg: Optional[_Segment] = None
        self.pending = None  # (event index, x at event) to apply at self.t
        self.n_steps = 0
        self.n_rejected = 0
        self._budget = float(s.max_steps_per_second) * BUDGET_WINDOW
        self._win_t0, self._win_n, self._warned = self.t, 0, False
        self._warn_n = BUDGET_WARN_FRACTION * self._budget
        self._call_budget = float(s.max_steps_per_call)
        # guards exactly at zero fire if the motion leaves them towards their after side: at the start,
        # and after a jump every guard but the one of the event just handled (that one stays disarmed)
        self._at_start = True
        self._disarmed = -1  # index of the event whose guard stays disarmed at zero
        try:
            self.x = [float(v) for v in x]
            self.pair = self.pair.specialized(len(self.x))  # the step unrolled for this many states
            self.q = dict(q)
            self.x_out, self.q_out = self.x, self.q  # state served at t_out
            self._stateless = not self.x
            self._check_domain(self.t, self.x)
            self._bind()
            self._check_initial_rates()
            # a given first step is taken as it is, but never below the collapse limit
            self.h = (max(float(s.initial_step), START_STEP_ULPS * EPS * max(abs(self.t), 1.0))
                      if s.initial_step > 0 else self._initial_step())
        except (ArithmeticError, ValueError) as exc:
            if isinstance(exc, ModelError):
                raise
            raise self._arithmetic_error(exc, "initialization") from None

    # ---- setup helpers ----------------------------------------------------------------------
    def _check_initial_rates(self):
        bad = [(v.name, d) for v, d in zip(self.model.states, self.f) if not math.isfinite(d)]
        if bad:
            name, d = bad[0]
            raise DomainError(f"the rate d{name}/dt = {d!r} at the start (t = {self.t!r} s) is not finite: "
                              f"{_extreme_parameters(self.p)}")

    def _bind(self):
        """(Re)bind the right-hand side and the active guards to the current (q, u)."""
        self._rebind()
        self.f = self.fun(self.t, self.x)
        self.g = [ev.guard(self.x, self.q, self.u, self.p) for _, ev in self.active]
        self._g_prev = None  # guards at the start of the previous step (None after a restart)

    def _rebind(self):
        model, q, u, p = self.model, self.q, self.u, self.p
        if model.bind is not None:
            self.fun = model.bind(q, u, p)
        else:
            flow = model.flow
            self.fun = lambda t, x: flow(t, x, q, u, p)
        self.active = [(i, ev) for i, ev in enumerate(model.events) if ev.active(q)]

    def _initial_step(self):
        """Hairer's starting step (Solving ODEs I, Sect. II.4), never below START_STEP_ULPS ulps
        of ``max(|t|, 1)`` (with a very tight ``abs_tol`` on a state that starts at 0 with a
        nonzero rate, the estimate ``100 h0`` is far below what the error control needs) and safe
        against overflow in the norms."""
        t, y, f = self.t, self.x, self.f
        floor = min(START_STEP_ULPS * EPS * max(abs(t), 1.0), self.max_step)
        if not y:
            return self.max_step if math.isfinite(self.max_step) else 1.0
        scale = [self.atol + abs(v) * self.rtol for v in y]
        d0 = _rms([a / b for a, b in zip(y, scale)])
        d1 = _rms([a / b for a, b in zip(f, scale)])
        h0 = 1e-6 if not (d0 >= 1e-5 and d1 >= 1e-5) else 0.01 * d0 / d1
        if not h0 >= floor:  # also NaN (inf/inf)
            h0 = floor
        h0 = min(h0, self.max_step)
        y1 = [a + h0 * b for a, b in zip(y, f)]
        f1 = self.fun(t + h0, y1)
        d2 = _rms([(a - b) / c for a, b, c in zip(f1, f, scale)]) / h0
        if d1 <= 1e-15 and d2 <= 1e-15:
            h1 = max(1e-6, h0 * 1e-3)
        else:  # exponent 1/(p+1) with p the order of the error estimate: 4 and 7
            d = max(d1, d2)
            h1 = (0.01 / d) ** (1.0 / self.pair.order) if math.isfinite(d) else 0.0
        h = min(100 * h0, h1, self.max_step)
        return h if h >= floor else floor

    # ---- public API -------------------------------------------------------------------------
    @property
    def events(self) -> List[EventRecord]:
        """The full event history (only with ``keep_history`` / ``log_events = 1``)."""
        if self._history is None:
            raise RuntimeError("the full event history is kept only with log_events = 1 (or keep_history=True); "
                               "n_events and last_event are always available")
        return self._history

    def set_input(self, u):
        """Change the inputs from the latest communication time on."""
        u = tuple(float(v) for v in u)
        if u == self.u:
            return
        check_inputs(self.model, u)
        crossed = None
        if self.t > self.t_out:
            # the integrator ran ahead: redo the step exactly up to the communication time
            seg = self.seg
            if self.t_out == seg.t0:
                x = seg.y0
            else:
                x, _, _ = self.pair.step(seg.fun, seg.t0, seg.y0, seg.f0, self.t_out - seg.t0)
                crossed = self._crossed_in(seg.y0, x)
            self.t, self.x = self.t_out, x
            self.pending = None
            self.seg = None
        self.u = u
        try:
            self._bind()
            # a restart like after a jump: the dynamics with the new input may be much faster, and
            # a step grown on an exactly integrated flight could hold a whole arc of a guard
            self.h = min(self.h, self._initial_step())
        except ArithmeticError as exc:
            raise self._arithmetic_error(exc, f"the input change at t = {self.t!r} s") from None
        if crossed is not None:
            self.pending = (crossed, self.x)
        # a restart: guards exactly at zero are armed as at the start (a foot at z = 0 to the last
        # bit when the thrust switches off must still touch down), but for the guard of an event
        # handled at this very instant
        last = self.last_event
        self._at_start = True
        self._disarmed = last.index if last is not None and last.time == self.t else -1

    def _crossed_in(self, y0, y1):
        """Index of the first active event (in priority order) whose guard is on its "before" side
        at ``y0`` (the start of the step being redone) and on its "after" side at ``y1``, else None.

        Used when a step that ran ahead is redone up to an input change: the run-ahead step saw
        the guard touch zero without crossing (a foot whose height reaches exactly 0 with zero
        speed at the switching instant, found by the property suite), but the exact state at the
        communication point lies on or beyond the guard.  The event happens there."""
        q, u, p = self.q, self.u, self.p
        last = self.last_event
        disarmed = last.index if last is not None and last.time == self.seg.t0 else -1
        for i, ev in self.active:
            sgn = -1.0 if ev.direction == FALLING else 1.0
            g0, g1 = sgn * ev.guard(y0, q, u, p), sgn * ev.guard(y1, q, u, p)
            # also a guard exactly at zero at the start of the step (armed: not the event handled
            # there) that ends beyond zero: a hop of zero length, z = 0 -> 1e-17 -> -3e-18 m
            if g1 >= 0.0 and (g0 < 0.0 or (g0 == 0.0 < g1 and i != disarmed)):
                return i
        return None

    def advance(self, t_target: float):
        """Integrate to ``t_target`` (handling every event on the way); return ``(x, q)`` there."""
        if self.t_out <= t_target < self.t:  # the common call: inside the step taken ahead
            seg = self.seg
            x = seg.y0 if t_target == seg.t0 else (seg._dense or seg.dense())(t_target)
            self.t_out, self.x_out, self.q_out = t_target, x, self.q
            return x, self.q
        if t_target < self.t_out:
            raise ValueError(f"cannot go back in time: t = {t_target} < {self.t_out}")
        if self._stateless:
            # no states: nothing to integrate, and no guard can change between input changes
            self.t = self.t_out = max(self.t, t_target)
            self.q_out = self.q
            return self.x_out, self.q_out
        self._run(t_target, apply_events=True)
        self.t_out = t_target
        self.x_out = self.x if t_target == self.t else self.seg(t_target)
        self.q_out = self.q
        return self.x_out, self.q_out

    # the only containers the simulator changes in place (it appends to them): copied by
    # snapshot/restore; every other field is replaced, never mutated — states, rates and guards
    # are new lists at each step, q a new dict at each jump, a segment is written once — so a
    # snapshot shares them (a deep copy cost 0.2 ms per fmi2GetFMUstate, the SSP master's rollback
    # saves one per communication step)
    _SHALLOW = ("_history", "new_events", "new_warnings", "_recent")

    def snapshot(self):
        """A copy of the whole integrator state (for fmi2GetFMUstate), of constant size unless
        the full history is kept.

        The model, the parameters, the method and every value the simulator never mutates in
        place are shared, not copied; closures are rebuilt on restore (the discrete state ``q`` is
        never mutated in place, so the right-hand sides kept in past segments stay valid).
        """
        state = self._copy_state(self.__dict__)
        del state["fun"], state["active"]  # closures: rebuilt on restore
        return state

    def restore(self, snap):
        self.__dict__.update(self._copy_state(snap))
        self._rebind()

    @classmethod
    def _copy_state(cls, state):
        """A copy of a state dict: the containers of _SHALLOW copied (shallowly: their items are
        never mutated), everything else shared."""
        out = state.copy()
        for k in cls._SHALLOW:
            v = state[k]
            if v is not None:
                out[k] = v.copy()  # (lists and a deque: copy() keeps the deque's maxlen)
        return out

    def advance_to_event(self, t_target: float) -> bool:
        """Like :meth:`advance`, but stop at the first event on the way, *before* its jump.

        Returns True when an event lies in ``(t_out, t_target]``: then ``t_out`` is its exact time
        and ``x_out`` the state there, on the guard; the jump stays pending and the next
        :meth:`advance` (e.g. ``advance(t_out)``) applies it.  Otherwise it is ``advance(t_target)``
        and returns False.  The step sequence is that of :meth:`advance`: stopping changes no
        event time (FMI 3.0 co-simulation with early return).
        """
        if t_target < self.t_out:
            raise ValueError(f"cannot go back in time: t = {t_target} < {self.t_out}")
        if not self.model.events or self._stateless:  # nothing to stop at (a model without states
            self.advance(t_target)                  # changes only with its inputs, held over a step)
            return False
        self._run(t_target, apply_events=False)
        if self.pending is not None and self.t <= t_target:
            self.t_out, self.x_out, self.q_out = self.t, self.x, self.q
            return True
        self.advance(t_target)
        return False

    def apply_event(self, index: int, t: float, x) -> list:
        """Apply the jump of event ``index`` at time ``t`` to the state ``x`` located by someone
        else (an FMI 3.0 model-exchange importer's solver); returns the new continuous state.
        Records, Zeno and domain checks as for an event the engine located itself."""
        self.t = self.t_out = float(t)
        self.x = [float(v) for v in x]
        self.seg = None
        self.pending = (index, self.x)
        self.apply_pending_event()
        self.x_out, self.q_out = self.x, self.q
        return self.x

    def restart_at(self, t: float, x, u) -> None:
        """Go on from the state ``x`` at time ``t`` given from outside (an FMI 3.0 model-exchange
        importer's solver) with the inputs ``u``: the step taken ahead and any located event are
        dropped."""
        self.t = self.t_out = float(t)
        self.x = self.x_out = [float(v) for v in x]
        self.seg, self.pending = None, None
        self.set_input(u)

    @property
    def event_due(self) -> bool:
        """A located event's jump is pending at the time served last (after :meth:`advance_to_event`)."""
        return self.pending is not None and self.t == self.t_out

    def domain_problem(self, t: float, x) -> Optional[str]:
        """The model's domain condition at ``(t, x)`` in the current mode: None or its text."""
        return self.model.domain(t, x, self.q, self.u, self.p, self._slack)

    # ---- stepping ---------------------------------------------------------------------------
    def _run(self, t_target, apply_events):
        """Step until the integrator reaches ``t_target`` — applying every located event's jump on
        the way (``apply_events``), or stopping at the first one, its jump left pending; an
        arithmetic failure in the model becomes a :class:`DomainError` naming the time.  One run
        takes at most ``max_steps_per_call`` step attempts (accepted and rejected): the bound on how
        long one call of an importer blocks, whatever its communication step."""
        limit = self.n_steps + self.n_rejected + self._call_budget
        try:
            while True:
                if self.pending is not None:
                    if not apply_events:
                        return
                    if t_target >= self.t:
                        self.apply_pending_event()
                        continue
                if t_target <= self.t:
                    return
                if self.n_steps + self.n_rejected >= limit:
                    raise self._call_budget_error(t_target)
                self._step(t_target)
        except (ArithmeticError, ValueError) as exc:
            if isinstance(exc, ModelError):
                raise
            raise self._arithmetic_error(exc, f"t = {self.t!r} s") from None

    def _step(self, t_target=math.inf):
        pair, fun = self.pair, self.fun
        t, y, f = self.t, self.x, self.f
        h = min(self.h, self.max_step, UNBOUNDED_STEP_FACTOR * max(abs(t), 1.0))
        rejected = False
        while True:
            t_new = t + h
            if t_new >= self.t_stop > t + 10 * EPS * max(abs(t), 1.0):
                t_new = self.t_stop  # land on the stop time (unless a rounding error away from it)
            h = t_new - t  # the step actually taken: t + h is rounded (found by the benchmark)
            if h <= MIN_STEP_ULPS * EPS * max(abs(t), 1.0):
                raise self._collapse_error(t, h)
            y_new, f_new, K = pair.step(fun, t, y, f, h)
            n = self._win_n = self._win_n + 1  # the work budget (_spend), fast path inline
            if n >= self._warn_n or t - self._win_t0 >= BUDGET_WINDOW:
                self._spend(t, h)
            err = pair.error_norm(K, h, y, y_new, self.atol, self.rtol)
            if err < 1.0:  # False for NaN: a non-finite step is rejected
                factor = MAX_FACTOR if err == 0.0 else min(MAX_FACTOR, SAFETY * err ** pair.error_exponent)
                if rejected:
                    factor = min(1.0, factor)
                self.h = min(h * factor, self.max_step)
                break
            self.n_rejected += 1
            rejected = True
            if not math.isfinite(err):
                h *= MIN_FACTOR
            else:
                h *= max(MIN_FACTOR, SAFETY * err ** pair.error_exponent)
        self.n_steps += 1
        at_start, self._at_start = self._at_start, False
        disarmed = self._disarmed
        seg = _Segment(t, t_new, y, y_new, f, K, fun, pair)
        # ---- event detection on the accepted step ----
        q, u, p = self.q, self.u, self.p
        g_new = [ev.guard(y_new, q, u, p) for _, ev in self.active]
        if at_start and any(g0 == 0.0 == g1 for g0, g1 in zip(self.g, g_new)):
            # a guard still exactly at zero (the first steps are tiny: x = g t^2/2 is below an ulp
            # of the leg length): it stays armed until the motion leaves zero
            self._at_start = True
        hit = None
        g, g_prev = self.g, self._g_prev
        for k, ((i, ev), g0, g1) in enumerate(zip(self.active, g, g_new)):
            sgn = -1.0 if ev.direction == FALLING else 1.0  # before side: sgn*g < 0; after: >= 0
            if sgn * g1 < 0.0:
                if sgn * g0 >= 0.0 or (g_prev is not None and sgn * (g0 - g_prev[k]) < 0.0):
                    continue  # (receding from zero over the previous step: no turn towards it in this one)
                te = self._hidden_crossing(seg, ev, sgn, g0, g1, f_new)
                if te is None:
                    continue
            elif sgn * g0 < 0.0:
                te = self._locate(seg, ev, t, g0, g1)
            elif g0 == 0.0:
                te = self._locate_from_zero(seg, ev, g1, at_start and i != disarmed)
                if te is None:
                    continue
            else:
                te = self._hidden_return(seg, ev, sgn, g0, g1, f_new, at_start and i == disarmed)
                if te is None:
                    continue
            if hit is None or te < hit[0]:
                hit = (te, k)
        if hit is None:
            if (self.model.domain(t_new, y_new, q, u, p, self._slack) is None and all(map(math.isfinite, y_new))) \
                    or not self._end_step(seg, t_target):
                self.seg, self.t, self.x, self.f, self.g = seg, t_new, y_new, f_new, g_new
                self._g_prev = g  # guards at the start of the step (the secant's direction)
            return
        te, k = hit
        i, ev = self.active[k]
        if te == t:
            # a guard exactly at zero at the start, the motion leaving to its after side: the event
            # happens at the start (e.g. a stick at its free length moving up lifts off at t0)
            self.seg, self.x, self.f, self.pending = None, y, f, (i, y)
            return
        if te < t_new:
            te, y_e, f_e, K_e = self._land_on_event(seg, ev, te)
            seg = _Segment(t, te, y, y_e, f, K_e, fun, pair)
        else:
            y_e, f_e = y_new, f_new
        if not self._end_step(seg, t_target):
            self.seg, self.t, self.x, self.f = seg, te, y_e, f_e
            self.pending = (i, y_e)

    # ---- work budget (issue 9 item 2) ----------------------------------------------------------
    def _spend(self, t, h):
        """The work budget, once a step attempt has been counted in ``_win_n`` (in ``_step``) and the
        window is full or over: windows of BUDGET_WINDOW s of simulated time, a warning at
        BUDGET_WARN_FRACTION of a window's ``max_steps_per_second``, an error at all of it."""
        if t - self._win_t0 >= BUDGET_WINDOW:
            self._win_t0, self._win_n = t, 1  # a new window, with this attempt in it
        n = self._win_n
        if n < self._warn_n:
            return
        elapsed = max(t + h - self._win_t0, 0.0)
        if n >= self._budget:
            raise ModelError(
                f"work budget exhausted: {n} internal steps within {elapsed:.3g} s of simulated time up to "
                f"t = {t:.10g} s (max_steps_per_second = {self.solver.max_steps_per_second:g}; mean step "
                f"{elapsed / n:.3g} s, latest {h:.3g} s). The model is stiff here: "
                f"{self._stiffness_text()}. To change: make the fastest time scale slower "
                f"(the parameters named above), or raise max_steps_per_second to let the run go on slowly")
        if not self._warned:
            self._warned = True
            self.new_warnings.append(
                f"stiff: {n} internal steps within {elapsed:.3g} s of simulated time up to t = {t:.10g} s "
                f"(mean step {elapsed / n:.3g} s); the run stops at max_steps_per_second = "
                f"{self.solver.max_steps_per_second:g} steps per simulated second. "
                f"{self._stiffness_text()}")

    def _call_budget_error(self, t_target):
        return ModelError(
            f"max_steps_per_call = {self.solver.max_steps_per_call:g} internal steps taken in one call, "
            f"from t = {self.t_out:.10g} s to t = {self.t:.10g} s of a call up to t = {t_target:.10g} s. "
            f"To change: use shorter communication steps, or raise the parameter max_steps_per_call "
            f"to let one call take longer")

    def _stiffness_text(self):
        parts = []
        scales = _time_scales(self.model, self.p)
        if scales:
            fast = sorted(scales, key=lambda s: s[2])[:2]
            parts.append("fastest time scales of the model: " + "; ".join(
                f"{label} = {value:.3g} s ({', '.join(f'{n} = {self.p[n]!r}' for n in names)})"
                for label, names, value in fast))
        return "; ".join(parts) if parts else "the error control forces steps this small"

    def _collapse_error(self, t, h):
        last = self.last_event
        if last is not None and last.time == t:
            recent = [e for e in self._recent if t - e[0] <= self.zeno_window]
            if len(recent) >= STORM_EVENTS:
                return ZenoError(
                    f"event storm: the step size collapsed to {h:.3g} s right after event {self.n_events} "
                    f"({last.name}) at t = {t:.15g} s, the latest {len(recent)} events within "
                    f"{t - recent[0][0]:.3g} s: the events accumulate (Zeno behaviour)")
            return ModelError(
                f"step size collapsed to {h:.3g} s right after event {self.n_events} ({last.name}) at "
                f"t = {t:.15g} s: the dynamics after the event are too fast to resolve or singular "
                f"({self._stiffness_text()})")
        return ModelError(
            f"step size collapsed to {h:.3g} s at t = {t:.15g} s: the error estimate cannot be met with "
            f"rel_tol = {self.solver.rel_tol!r}, abs_tol = {self.solver.abs_tol!r} (the model is stiff or singular here, "
            f"or the tolerances lie below the rounding error of the states)")

    def _arithmetic_error(self, exc, where):
        kind = {ZeroDivisionError: "division by zero", OverflowError: "overflow"}.get(type(exc), "domain error")
        detail = exc.args[-1] if exc.args and isinstance(exc.args[-1], str) else str(exc)
        return DomainError(f"floating-point {kind} in the model at {where} ({detail}): "
                           f"{_extreme_parameters(self.p)}")

    def _land_on_event(self, seg, ev, te):
        """Redo the step exactly up to the event, so that the state there has the method's full
        order, and make that state lie on the guard.

        ``te`` comes from the dense output; a step of exactly ``te - t0`` lands a little off the
        guard (by the interpolant's error: e.g. a penetration of -1e-9 m at a liftoff, or an SMA
        plateau entered 3e-10 m early).  A few secant iterations on the map
        ``tau -> guard(step(t0, tau - t0))`` (a polynomial in the step size) move the event to
        where the integrated solution itself meets the guard.  Returns ``(te, y, f, K)``.
        """
        q, u, p, guard = self.q, self.u, self.p, ev.guard
        t0, t1, y0, f0 = seg.t0, seg.t1, seg.y0, seg.f0
        step, fun = self.pair.step, seg.fun
        y_a, f_a, K_a = step(fun, t0, y0, f0, te - t0)
        g_a = guard(y_a, q, u, p)
        best = (abs(g_a), te, y_a, f_a, K_a)
        d = 1e-3 * (te - t0)
        slope = (guard(seg(te), q, u, p) - guard(seg(te - d), q, u, p)) / d  # from the dense output
        ta, tb = te, (te - g_a / slope if slope else te)
        tol = 4 * EPS * max(abs(te), 1.0)
        for _ in range(8):
            if g_a == 0.0 or not (t0 < tb < t1) or abs(tb - ta) <= tol:
                break
            y_b, f_b, K_b = step(fun, t0, y0, f0, tb - t0)
            g_b = guard(y_b, q, u, p)
            if abs(g_b) < best[0]:
                best = (abs(g_b), tb, y_b, f_b, K_b)
            if g_b == g_a:
                break
            ta, g_a, tb = tb, g_b, tb - g_b * (tb - ta) / (g_b - g_a)
        return best[1:]

    def _locate_from_zero(self, seg, ev, g1, at_start=False):
        """A guard that starts the step exactly at zero and ends it on the after side: when did it
        cross?  If it visits the before side first, the crossing is located from there: a large
        first step after a jump (a flight parabola is integrated exactly, so the step size grows
        fast) may hold a whole arc, so the dense output is probed near the start.  If the motion
        leaves zero straight towards the after side, the event happens at the start of the step
        when ``at_start`` (the start of the simulation, or after a jump for every guard but the one
        of the event just handled: a stick at its free length moving up lifts off at t0, a liftoff
        with the mass already moving down touches down at once, issue 9 item 1); else (the guard
        of the event just handled) it stays disarmed."""
        q, u, p = self.q, self.u, self.p
        sgn = -1.0 if ev.direction == FALLING else 1.0
        h = seg.t1 - seg.t0
        for frac in (1e-7, 1e-4, 1e-2, 0.1, 0.5):
            tp = seg.t0 + frac * h
            gp = ev.guard(seg(tp), q, u, p)
            if sgn * gp < 0.0:
                return self._locate(seg, ev, tp, gp, g1)
            if gp != 0.0:
                # left zero towards the after side: no crossing from the before side
                return seg.t0 if at_start else None
        return seg.t0 if at_start and g1 != 0.0 else None

    def _turning_point(self, seg, ev, sgn, g0, g1, f1):
        """``(tp, g(tp))`` where ``sgn * g`` turns from rising to falling inside the step (slopes by a
        difference along the flow at both ends: ``sgn * g`` rises at the start and falls at the end),
        the maximum of the cubic Hermite interpolant of ``sgn * g`` probed on the dense output; or
        None when it does not turn so."""
        q, u, p, guard = self.q, self.u, self.p, ev.guard
        t0, h = seg.t0, seg.t1 - seg.t0
        eps = 1e-6 * h
        d0 = sgn * (guard([a + eps * b for a, b in zip(seg.y0, seg.f0)], q, u, p) - g0) / eps * h
        if not d0 > 0.0:
            return None
        d1 = sgn * (guard([a + eps * b for a, b in zip(seg.y1, f1)], q, u, p) - g1) / eps * h
        if not d1 < 0.0:
            return None
        G0, G1 = sgn * g0, sgn * g1
        # G'(tau) of the Hermite cubic, a quadratic with G'(0) = d0 > 0 > d1 = G'(1): bisect its root
        A = 6 * G0 + 3 * d0 - 6 * G1 + 3 * d1
        B = -6 * G0 - 4 * d0 + 6 * G1 - 2 * d1
        lo, hi = 0.0, 1.0
        for _ in range(40):
            mid = 0.5 * (lo + hi)
            if (A * mid + B) * mid + d0 > 0.0:
                lo = mid
            else:
                hi = mid
        tp = t0 + lo * h
        if not t0 < tp < seg.t1:
            return None
        return tp, guard(seg(tp), q, u, p)

    def _hidden_crossing(self, seg, ev, sgn, g0, g1, f1):
        """Both ends of the step on the guard's before side: did the guard cross zero and come back
        inside the step?  (A flight parabola is integrated exactly, so the error control lets a
        step hold a foot that dips below the ground and rises again, e.g. under a switching
        thrust; in contact a Penetrator's penetration may dip below 0 and back: found by the
        property suite and scans of such runs.)  Only when the guard approaches zero at the start
        and recedes at the end: if the guard is on its after side at its turning point, the
        crossing is located between the start and that point."""
        turn = self._turning_point(seg, ev, sgn, g0, g1, f1)
        if turn is None or sgn * turn[1] < 0.0:
            return None
        return self._locate(seg, ev, seg.t0, g0, turn[1], b=turn[0])

    def _hidden_return(self, seg, ev, sgn, g0, g1, f1, own):
        """Both ends of the step on the guard's after side: did the guard visit its before side and
        come back, an event inside the step?  (A bouncing ball near its accumulation point hops for
        less than a step.)  Only when the guard heads for zero at the start and away from it at the
        end: if it is on its before side at its turning point, the event is located between that
        point and the end of the step.  If not, and this is the first step after this event's own
        jump (``own``) ending further past zero than it began, the guard went back past zero within
        the rounding of the event's location: the events accumulate faster than the steps resolve
        them, an event storm — never a result on the wrong side of an active guard."""
        turn = self._turning_point(seg, ev, -sgn, g0, g1, f1)
        if turn is None:
            return None
        tp, gp = turn
        if sgn * gp < 0.0:
            return self._locate(seg, ev, tp, gp, g1)
        if own and sgn * g1 > sgn * g0:
            raise ZenoError(
                f"event storm: {ev.name} happens again within the rounding of its own location at t = "
                f"{seg.t0:.15g} s (its guard heads back to zero after the jump and is past it again at t = "
                f"{seg.t1:.15g} s, guard = {g1!r}): the events accumulate faster than the steps resolve them "
                f"(Zeno behaviour, e.g. a bouncing ball coming to rest). Model the rest (a mode without this event "
                f"once the motion is small), or stop before this time")
        return None

    def _locate(self, seg, ev, a, ga, gb, b=None):
        """Earliest time in ``[a, b]`` (``b`` the end of the step unless given) where ``ev``'s guard
        crosses zero in its direction.

        Illinois iteration keeping a bracket ``[a, b]`` with the guard strictly on the before side
        at ``a`` and on the after side at ``b``; returns ``b`` (the event has happened there).
        """
        q, u, p = self.q, self.u, self.p
        guard = ev.guard
        sgn = -1.0 if ev.direction == FALLING else 1.0  # after side: sgn*g >= 0
        b = seg.t1 if b is None else b
        fa, fb = sgn * ga, sgn * gb  # fa < 0 <= fb
        side = 0
        tol = 4 * EPS * max(abs(a), abs(b), 1e-300)
        for _ in range(200):
            if b - a <= tol:
                break
            c = b - fb * (b - a) / (fb - fa)
            if not (a < c < b):
                c = 0.5 * (a + b)
            fc = sgn * guard(seg(c), q, u, p)
            if fc >= 0.0:
                b, fb = c, fc
                if side == 1:
                    fa *= 0.5
                side = 1
            else:
                a, fa = c, fc
                if side == -1:
                    fb *= 0.5
                side = -1
            if fc == 0.0:
                break
        return b

    def apply_pending_event(self):
        """Apply the jump of the event located at ``self.t`` (the engine does this itself inside
        :meth:`advance`); records it in constant memory (count, last event, recent times) and in
        the history when it is kept."""
        i, x_before = self.pending
        ev = self.model.events[i]
        x_new, q_new = ev.jump(self.x, self.q, self.u, self.p)
        x_new = [float(v) for v in x_new]
        record = EventRecord(self.t, ev.name, i, list(x_before), x_new)
        self.n_events += 1
        self.last_event = record
        self._recent.append((self.t, ev.name))
        if self._history is not None:
            self._history.append(record)
            self.new_events.append(record)
        self.pending = None
        self._at_start, self._disarmed = True, i
        self.x, self.q = list(x_new), dict(q_new)
        self._check_zeno()
        self._check_domain(self.t, self.x)
        self._bind()
        # clean restart: the dynamics after a jump may be much faster than before it (the step
        # size grows tenfold per step on an exactly integrated flight parabola); never restart
        # with a step larger than the starting-step estimate for the new state
        self.h = min(self.h, self._initial_step())

    def _check_zeno(self):
        n = self.zeno_max_events
        recent = self._recent
        if self.n_events >= n:
            first = recent[-n][0]
            if self.t - first <= self.zeno_window:
                names = ", ".join(sorted({name for _, name in list(recent)[-n:]}))
                raise ZenoError(
                    f"event storm: {n} events ({names}) within {self.t - first:.3g} s up to "
                    f"t = {self.t:.15g} s (Zeno behaviour; limit {n} events per {self.zeno_window:g} s)")

    def _check_domain(self, t, x, seg=None):
        violation = self._domain_violation(t, x, seg)
        if violation is not None:
            raise _domain_error(violation)

    def _domain_violation(self, t, x, seg=None):
        """None, or ``(t_v, text)``: the first time in ``seg`` (bisected) where the model's domain
        condition fails, and the condition's text (with the values at the end of the step)."""
        domain = self.model.domain
        msg = domain(t, x, self.q, self.u, self.p, self._slack)
        if msg is None:
            if not all(map(math.isfinite, x)):
                bad = ", ".join(f"{v.name} = {a!r}" for v, a in zip(self.model.states, x) if not math.isfinite(a))
                raise DomainError(f"the state became non-finite at t = {t:.15g} s ({bad}): "
                                  f"{_extreme_parameters(self.p)}")
            return None
        if seg is not None:
            # bisect for the first time the condition is violated
            a, b = seg.t0, t
            for _ in range(60):
                c = 0.5 * (a + b)
                if domain(c, seg(c), self.q, self.u, self.p, self._slack) is None:
                    a = c
                else:
                    b = c
            t = b
        return t, msg

    def _end_step(self, seg, t_target):
        """Commit the step ``seg`` unless the trajectory leaves the domain in it.  A violation that
        lies beyond ``t_target`` (the integrator runs ahead of the communication point, with
        steps up to 1e7 s on an unbounded flight parabola) is not reported before its time: the
        step is cut exactly at ``t_target`` and the next call goes on from there.  True if cut."""
        violation = self._domain_violation(seg.t1, seg.y1, seg)
        if violation is None:
            return False
        if violation[0] > t_target > seg.t0:
            t, y, f = seg.t0, seg.y0, seg.f0
            y_c, f_c, K_c = self.pair.step(seg.fun, t, y, f, t_target - t)
            self.seg = _Segment(t, t_target, y, y_c, f, K_c, seg.fun, self.pair)
            self.t, self.x, self.f = t_target, y_c, f_c
            self.g = [ev.guard(y_c, self.q, self.u, self.p) for _, ev in self.active]
            self._g_prev = None
            return True
        raise _domain_error(violation)


def _domain_error(violation):
    t, condition = violation
    return DomainError(f"the trajectory left the model's domain at t = {t:.10g} s: {condition}")


# =============================================================================================
# the start of a run: every check and the initial state (pure: the native FMUs run it as C)
# =============================================================================================

def prepare(model: HybridModel, p, s, u):
    """The rules of a run, checked in this order, and its initial state ``(x0, q0)``: the
    solver's settings ``s``, the model's parameters ``p``, the inputs ``u``, the model's time
    scales, its initial state, the absolute tolerance against its scales. Each refusal names the
    parameter, its value and the rule. A pure function of its arguments: the code generator
    traces it into the native FMUs' initialization (issue 18)."""
    check_solver_parameters(s, has_states=bool(model.states))
    model.check_parameters(p)
    check_inputs(model, u)
    _check_time_scales(model, p)
    x, q = model.initial(p)
    check_abs_tol(model, p, s, x)
    return x, q


def check_inputs(model: HybridModel, u):
    for var, v in zip(model.inputs, u):
        if not fmath.isfinite(v):
            raise ParameterError(f"input {var.name} = {v!r} violates the rule: {var.name} must be finite")


def check_abs_tol(model: HybridModel, p, s, x):
    """Issue 9 item 7: an absolute tolerance of the order of the motion itself controls nothing
    (abs_tol = 1 m on a 1.5 m drop let the energy balance drift by 90 %).  The scale is the
    smallest of the model's declared magnitudes (``error_scales``: static deflections, the free
    leg length, ...), else the largest initial state magnitude."""
    if model.error_scales is not None:
        scales = [e for e in model.error_scales(p) if e[2] > 0 and fmath.isfinite(e[2])]
    else:
        scales = []
    if not scales:
        big = max((abs(v) for v in x), default=0.0)
        scales = [("the largest initial state magnitude", (), big)] if big > 0 else []
    if not scales:
        return
    label, names, scale = min(scales, key=lambda e: e[2])
    limit = ABS_TOL_MAX_FRACTION * scale
    if s.abs_tol > limit:
        of = f" with {', '.join(f'{n} = {p[n]!r}' for n in names)}" if names else ""
        raise ParameterError(
            f"parameter abs_tol = {s.abs_tol!r} violates the rule: abs_tol <= {ABS_TOL_MAX_FRACTION:g} x "
            f"{label} ({scale:.6g}{of}) = {limit:.3g}; a larger absolute tolerance lets the local error be "
            f"as large as the motion itself and controls nothing")


# =============================================================================================
# parameter magnitudes and physical time scales (issue 9 items 2 and 6)
# =============================================================================================

def _time_scales(model, p):
    """The model's physical time scales ``(label, parameter names, seconds)`` (may be empty)."""
    if model.time_scales is None:
        return ()
    return tuple(s for s in model.time_scales(p) if s[2] > 0 and math.isfinite(s[2]))


def _check_time_scales(model, p):
    """Every physical time scale must be at least MIN_TIME_SCALE: faster dynamics (g = 1e300,
    k = 1e300, m = 1e-300, ...) are beyond what an explicit solver can resolve in double precision
    within any work budget, and used to end in raw ZeroDivisionError/OverflowError texts."""
    if model.time_scales is None:
        return
    for label, names, value in model.time_scales(p):
        if not value >= MIN_TIME_SCALE:
            values = ", ".join(f"{n} = {p[n]!r}" for n in names)
            raise ParameterError(
                f"parameter{'s' if len(names) > 1 else ''} {values} violate{'' if len(names) > 1 else 's'} "
                f"the rule: the time scale {label} = {value:.3g} s must be >= {MIN_TIME_SCALE:g} s (faster "
                f"dynamics are beyond the solver's resolution)")


def _extreme_parameters(p):
    """Text naming the model parameters of the most extreme magnitude (for arithmetic failures)."""
    mags = []
    for name, v in p.as_dict().items():
        if isinstance(v, bool) or not isinstance(v, (int, float)) or v == 0 or not math.isfinite(v):
            continue
        mags.append((abs(math.log10(abs(v))), name, v))
    mags.sort(reverse=True)
    named = ", ".join(f"{n} = {v!r}" for _, n, v in mags[:3])
    return (f"the values exceed floating-point range; parameters of the most extreme magnitude: {named}"
            if named else "the values exceed floating-point range")

