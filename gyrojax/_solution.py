"""Result codes shared by the simulation tiers and the fits."""

import diffrax


class RESULTS(diffrax.RESULTS):  # pyright: ignore[reportGeneralTypeIssues]
    """Why a computation ended. Messages say what to try.

    It extends diffrax's codes (themselves optimistix's and lineax's), so a solver's code carries over with
    `RESULTS.promote(...)`. gyrojax's own items (`root_find_failed`, `settle_max_steps`, `solver_failed`,
    `nonfinite_output`) have names of their own: an enumeration cannot redefine an inherited item.
    """

    root_find_failed = ("The steady-state root find did not converge. Try the averaged tier to see whether "
                        "the loops settle at all (an unstable or saturated loop has no equilibrium), or "
                        "raise `Steady(max_steps=...)`.")
    settle_max_steps = ("The ODE solver hit max_steps before the end of the settle window. Raise "
                        "`max_steps`, loosen rtol/atol, or shorten settle_time.")
    solver_failed = ("The ODE solver failed (step size collapsed or non-finite state). The loops may be "
                     "unstable for these parameters; check the loop gains and the stimulus amplitude.")
    nonfinite_output = "The result is NaN or infinite. Check the parameters for zeros and the stimulus for overload."


# Shown as `gyrojax.RESULTS<message>` (the public name), not by the private module that defines it.
RESULTS.__module__ = "gyrojax"


def result_code(result):
    """The integer code of a `RESULTS` item, an array of its shape (under `jit` too): for keeping codes where an
    enumeration item cannot go (NumPy arrays, `np.where` over devices). `result_message` reads one back."""
    return result._value


def result_message(code) -> str:
    """The message of one integer code of `RESULTS` ("" for `successful`)."""
    return RESULTS._index_to_message[int(code)]
