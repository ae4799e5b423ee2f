"""The strongly coupled algorithm (``--algorithm model-exchange``): the continuous states of every
component integrated as one system by CVODE (SUNDIALS, as fmpy ships it), with root finding over
every component's event indicators.

At every right-hand-side evaluation the components get the integrator's time and states, their
outputs are evaluated in update order (a component after those feeding its direct feed-through
inputs, so a controller's thrust is the law at this very state), every input is set from them,
and the derivatives are read: there is no coupling delay at all, and the result converges to the
continuous closed loop as the tolerances shrink, whatever the output grid (``--step``).

At a root of any event indicator the components enter Event Mode together and are iterated in
superdense time (the discrete iteration of the co-simulation master), the states are read back,
and CVODE restarts there; rows at the event give the left and right limits.
"""
from __future__ import annotations

import ctypes
import math

import numpy as np

from .algorithms import LEFT, RIGHT, grid_points
from .package import SSPError

MAX_EVENT_ITERATIONS = 100
MAX_EVENTS_PER_INSTANT = 100  # roots at one time without the integrator moving on: an event storm


class CoupledCVode:
    """CVODE over the concatenated states (BDF with a dense linear solver, scalar tolerances),
    with the root functions of every event indicator. ``rhs(t, x, dx)`` and ``roots(t, x, z)``
    work on numpy views of CVODE's vectors."""

    def __init__(self, nx, nz, x0, t0, rhs, roots, rel_tol, abs_tol, max_step=math.inf, max_steps=100_000):
        from fmpy.sundials import cvode as cv
        from fmpy.sundials import (CVodeSetLinearSolver, N_VNew_Serial, NV_DATA_S, SUNContext,
                                   SUNContext_Create, SUNDenseMatrix, SUNLinSol_Dense)
        from fmpy.sundials.libraries import sundials_cvode
        from fmpy.sundials.sundials_types import sunrealtype

        self.cv = cv
        self.nx = max(nx, 1)  # CVODE needs a state: a system of stateless components gets a dummy
        self.real_nx = nx
        self.nz = nz
        self._rhs, self._roots = rhs, roots
        self.ctx = SUNContext()
        cv_ok(SUNContext_Create(0, ctypes.byref(self.ctx)))  # SUN_COMM_NULL
        self.x = N_VNew_Serial(self.nx, self.ctx)
        self.px = NV_DATA_S(self.x)
        self.xv = np.ctypeslib.as_array(self.px, (self.nx,))
        self.xv[:] = 0.0
        self.xv[:nx] = x0
        self.mem = cv.CVodeCreate(cv.CV_BDF, self.ctx)
        self.f_ = cv.CVRhsFn(self._f)
        self.g_ = cv.CVRootFn(self._g)
        cv_ok(cv.CVodeInit(self.mem, self.f_, t0, self.x))
        ss = sundials_cvode.CVodeSStolerances
        ss.argtypes, ss.restype = [ctypes.c_void_p, sunrealtype, sunrealtype], ctypes.c_int
        cv_ok(ss(self.mem, rel_tol, abs_tol))
        cv_ok(cv.CVodeRootInit(self.mem, nz, self.g_))
        self.A = SUNDenseMatrix(self.nx, self.nx, self.ctx)
        self.LS = SUNLinSol_Dense(self.x, self.A, self.ctx)
        cv_ok(CVodeSetLinearSolver(self.mem, self.LS, self.A))
        if math.isfinite(max_step):
            cv_ok(cv.CVodeSetMaxStep(self.mem, max_step))
        cv_ok(cv.CVodeSetMaxNumSteps(self.mem, max_steps))
        cv_ok(cv.CVodeSetNoInactiveRootWarn(self.mem))
        self.error = None
        self.n_rhs = 0

    def _f(self, t, y, ydot, user_data):
        from fmpy.sundials import NV_DATA_S

        try:
            x = np.ctypeslib.as_array(NV_DATA_S(y), (self.nx,))
            dx = np.ctypeslib.as_array(NV_DATA_S(ydot), (self.nx,))
            self.n_rhs += 1
            self._rhs(t, x[:self.real_nx], dx)
            dx[self.real_nx:] = 0.0
            return 0
        except Exception as exc:  # noqa: BLE001 - reported after CVode returns (a C callback must not raise)
            self.error = exc
            return -1

    def _g(self, t, y, gout, user_data):
        from fmpy.sundials import NV_DATA_S

        try:
            x = np.ctypeslib.as_array(NV_DATA_S(y), (self.nx,))
            z = np.ctypeslib.as_array(gout, (max(self.nz, 1),))
            self._roots(t, x[:self.real_nx], z)
            return 0
        except Exception as exc:  # noqa: BLE001
            self.error = exc
            return -1

    def integrate(self, t_out):
        """Integrate towards ``t_out``; returns ``(t_reached, root found)`` with the states at
        ``t_reached`` in :attr:`xv`."""
        tret = ctypes.c_double(0.0)
        flag = self.cv.CVode(self.mem, t_out, self.x, ctypes.byref(tret), self.cv.CV_NORMAL)
        if self.error is not None:
            exc, self.error = self.error, None
            raise exc
        if flag < 0:
            raise SSPError(f"the model-exchange integrator (CVODE) failed at t = {tret.value!r} s with flag "
                           f"{flag} (the coupled system is too stiff for the tolerances, or a component's "
                           f"equations are singular there)")
        return tret.value, flag == self.cv.CV_ROOT_RETURN

    def restart(self, t, x):
        self.xv[:self.real_nx] = x
        cv_ok(self.cv.CVodeReInit(self.mem, t, self.x))

    def free(self):
        self.cv.CVodeFree(ctypes.byref(ctypes.c_void_p(self.mem)))


def cv_ok(flag):
    if flag != 0:
        raise SSPError(f"the model-exchange integrator (CVODE) could not be set up (flag {flag})")


class CoupledSystem:
    """The components of the system as one ODE: states, derivatives, event indicators, events."""

    def __init__(self, ex):
        self.ex = ex
        self.insts = ex.order
        self.xoff, self.zoff = {}, {}
        nx = nz = 0
        for inst in self.insts:
            self.xoff[inst.name], self.zoff[inst.name] = nx, nz
            nx += inst.nx
            nz += inst.nz
        self.nx, self.nz = nx, nz

    def states(self):
        x = np.zeros(self.nx)
        for inst in self.insts:
            inst.get_states(x, self.xoff[inst.name])
        return x

    def evaluate(self, t, x):
        """Every component at ``(t, x)``: outputs in update order, then every input set."""
        ex = self.ex
        for inst in self.insts:
            inst.set_time(t)
            inst.set_states(x, self.xoff[inst.name])
        for inst in self.insts:  # (discrete inputs change only at events, in Event Mode)
            ex.feed(inst, continuous=True)
            ex.read(inst)
        for inst in self.insts:  # inputs fed by components later in the order (no feed-through)
            ex.feed(inst, continuous=True)

    def rhs(self, t, x, dx):
        self.evaluate(t, x)
        for inst in self.insts:
            inst.get_derivatives(dx, self.xoff[inst.name])

    def roots(self, t, x, z):
        self.evaluate(t, x)
        for inst in self.insts:
            inst.get_indicators(z, self.zoff[inst.name])

    def completed_step(self, t):
        """fmi3CompletedIntegratorStep of every component; True if one asks for Event Mode."""
        enter = False
        for inst in self.insts:
            try:
                e, terminate = inst.completed_integrator_step()
            except Exception as exc:  # noqa: BLE001
                raise inst.fail(f"fmi3CompletedIntegratorStep at t = {t!r} s", exc) from None
            if terminate:
                raise SSPError(f"Component {inst.name} asked to terminate the simulation at t = {t!r} s")
            enter |= e
        return enter

    def event(self, t, in_event_mode=False):
        """Event Mode for every component at ``t`` (``in_event_mode``: they are already, after
        initialization), iterated until no component asks for another discrete update and no
        connected value changes; back to Continuous-Time Mode. Returns whether a state or an output
        changed."""
        ex = self.ex
        before = dict(ex.value)
        if not in_event_mode:
            for inst in self.insts:
                inst.enter_event_mode()
        busy = []
        for k in range(MAX_EVENT_ITERATIONS):
            busy = []
            for inst in self.insts:
                changed = ex.feed(inst)
                need, terminate, _ = inst.update_discrete_states()
                if terminate:
                    raise SSPError(f"Component {inst.name} asked to terminate the simulation at t = {t!r} s")
                changed |= ex.read(inst)
                if need or (changed and k > 0):
                    busy.append(inst.name)
            if not busy and k > 0:
                break
        else:
            raise SSPError(f"the discrete iteration at t = {t!r} s did not settle after {MAX_EVENT_ITERATIONS} "
                           f"iterations: {', '.join(sorted(set(busy)))} still changing")
        for inst in self.insts:
            inst.enter_continuous_time_mode()
        return ex.value != before


def model_exchange(ex, t0, t_end, step, rel_tol=1e-10, abs_tol=1e-12, progress=None):
    """Integrate the coupled system on the output grid ``t0 + k step`` (rows at every grid point,
    and the left and right limits at every event)."""
    sys_ = CoupledSystem(ex)
    for inst in sys_.insts:
        inst.t = t0
    sys_.event(t0, in_event_mode=True)  # (model exchange is in Event Mode after initialization)
    x = sys_.states()
    sys_.evaluate(t0, x)
    ex.row(t0)
    solver = CoupledCVode(sys_.nx, sys_.nz, x, t0, sys_.rhs, sys_.roots, rel_tol, abs_tol)
    try:
        t, stuck = t0, 0
        for T in grid_points(t0, t_end, step):
            while t < T:
                t_reached, root = solver.integrate(T)
                x = solver.xv[:sys_.nx].copy()
                sys_.evaluate(t_reached, x)
                enter = sys_.completed_step(t_reached)
                if root or enter:
                    left = ex.row_values(t_reached, LEFT)
                    changed = sys_.event(t_reached)
                    x_new = sys_.states()
                    sys_.evaluate(t_reached, x_new)
                    changed |= not np.array_equal(x_new, x)
                    if changed:  # (a root in the direction no event fires on changes nothing: no rows)
                        ex.record.add(left)
                        ex.event_sources.append((t_reached, ()))
                        if t_reached < T:
                            ex.row(t_reached, RIGHT)
                    x = x_new
                    solver.restart(t_reached, x)
                    stuck = stuck + 1 if t_reached == t else 0
                    if stuck > MAX_EVENTS_PER_INSTANT:
                        raise SSPError(f"{stuck} events at t = {t_reached!r} s without the integrator moving on "
                                       f"(an event storm)")
                t = t_reached
            ex.row(T)
            if progress:
                progress(T)
    finally:
        solver.free()
    ex.n_rhs = solver.n_rhs
    return t
