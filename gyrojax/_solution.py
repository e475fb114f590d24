"""Result codes shared by the simulation tiers and the fits."""

import equinox.internal as eqxi


class RESULTS(eqxi.Enumeration):
    """Why a computation ended. Messages say what to try."""

    successful = ""
    root_find_failed = ("The steady-state root find did not converge. Try the averaged tier to see whether "
                        "the loops settle at all (an unstable or saturated loop has no equilibrium), or "
                        "raise `Steady(max_steps=...)`.")
    max_steps_reached = ("The ODE solver hit max_steps before the end of the settle window. Raise "
                         "`max_steps`, loosen rtol/atol, or shorten settle_time.")
    solver_failed = ("The ODE solver failed (step size collapsed or non-finite state). The loops may be "
                     "unstable for these parameters; check the loop gains and the stimulus amplitude.")
    nonfinite = "The result is NaN or infinite. Check the parameters for zeros and the stimulus for overload."


# Shown as `gyrojax.RESULTS<message>` (the public name), not by the private module that defines it.
RESULTS.__module__ = "gyrojax"
