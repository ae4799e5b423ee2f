"""The references the engine, the FMUs and the master are held against, computed independently of
them: the basic stick's events in closed form at 40 digits (``closed_form``, mpmath) and the
SpaceHopper's continuous-time closed loop (``closed_loop``, the thrust law inside a scipy ODE).

Host-side code; never imported inside an FMU.
"""
