"""The `gyrojax` command line (docs/cli.md).

Exit codes:

- 0: success.
- 1: a computation failed (a point did not settle, a fit did not converge), or a number the data should give
  could not be determined (`metrics`, `compensate`: printed as "n/a" with the reason; the JSON holds null
  and the reason). Files written before the failure are complete.
- 2: a usage or data error (bad argument, unreadable or invalid file, an output path that cannot be written),
  reported without a traceback; output paths are checked before any data is read or any work is done.
- 3 (`identify`): fitted, but the model does not describe the data (its chi2 is too large for the noise, or a
  fitted parameter is implausible); the standard errors are also given scaled by sqrt(chi2_red).
- 4 (`identify`): the data do not determine the scale factor (it is printed as NaN, with the reason).
- 5 (`identify`): a fit file that predates these checks (status unknown).
  When devices differ, the worst status decides: not converged (1), not determined (4), unknown (5), model
  rejected (3). `diagnose` exits 0 whatever its verdict (explained, partly explained, unexplained: the
  diagnosis itself succeeded), 1 if its final fit did not converge.
- 128 + N: stopped by signal N (130 for SIGINT, 143 for SIGTERM). The first signal is turned into an
  exception, so the file being written is discarded (its temporary file removed) and the previous version is
  kept; it is acted on when the running computation returns to Python. The stop is also recorded and checked
  again between steps and before any output is moved into place (an exception raised by a signal handler is lost
  when the signal lands in a garbage-collector hook), so a stopped command never writes its outputs. The first
  signal restores the default handlers: a second signal kills the process at once (by that signal). Run as the
  program, a stopped command ends with `os._exit` after its cleanup (XLA's teardown at interpreter exit, in the
  middle of a compile, can crash).
"""

import argparse
import contextlib
import os
import signal
import sys
import threading

from ._cli import compensate, demo, describe, diagnose, identify, metrics, plan, simulate
from ._cli.common import EXIT_FAILED, EXIT_USAGE
from ._data.io import OutputPathError
from ._runtime import stop as _stop


EXIT_SIGNAL_BASE = 128

_EXIT_CODES = """exit codes: 0 success; 1 a computation failed, or a number the data should give could not be
determined (printed as n/a with the reason); 2 a usage or data error (no traceback; output paths are checked
before any work); identify: 3 fitted but the model does not describe the data, 4 the scale factor is not
determined by the data, 5 a fit file without status; 128+N stopped by signal N (130 SIGINT, 143 SIGTERM; the file being
written is discarded, the previous one kept)."""


_Interrupted = _stop.Interrupted
_SIGNALS = (signal.SIGTERM, signal.SIGINT)


@contextlib.contextmanager
def _signals_raise():
    """Turn the first SIGTERM or SIGINT into `_Interrupted` for the block, restoring the old handlers after.

    The first signal records the stop (`gyrojax._runtime.stop`, checked again at safe points: its exception may be
    lost), raises, and restores the default handlers, so that a second signal kills the process whatever it is doing.
    An `_Interrupted` that Python could not raise (a signal in a garbage-collector hook) is not reported as an
    ignored exception: the safe points act on it.
    """
    if threading.current_thread() is not threading.main_thread():
        yield  # signal handlers can only be set from the main thread
        return

    def handler(signum, frame):
        for s in _SIGNALS:
            signal.signal(s, signal.SIG_DFL)
        _stop.request(signum)
        raise _Interrupted(signum)

    previous_hook = sys.unraisablehook

    def unraisable(hook_args):
        if not isinstance(hook_args.exc_value, _Interrupted):
            previous_hook(hook_args)

    previous = {s: signal.signal(s, handler) for s in _SIGNALS}
    sys.unraisablehook = unraisable
    try:
        yield
    finally:
        sys.unraisablehook = previous_hook
        for s, h in previous.items():
            signal.signal(s, h)


def build_parser():
    parser = argparse.ArgumentParser(
        prog="gyrojax", epilog=_EXIT_CODES,
        description="Differentiable simulation and identification of MEMS Coriolis vibratory gyroscopes. "
                    "Data files are the tidy table of docs/data_format.md (CSV or Parquet): rates in deg/s, "
                    "gyro outputs in LSB, DAC amplitudes in V.")
    sub = parser.add_subparsers(dest="command", required=True)
    simulate.add_parser(sub)
    metrics.add_parser(sub)
    compensate.add_parser(sub)
    diagnose.add_parser(sub)
    plan.add_parser(sub)
    identify.add_parser(sub)
    demo.add_parser(sub)
    describe.add_parser(sub)
    return parser


def _os_error_text(e: OSError) -> str:
    if e.filename is None:
        return str(e)
    text = f"{e.filename}: {e.strerror or e}"
    return text + (f" (moving it to {e.filename2})" if e.filename2 is not None else "")


def main(argv=None):
    """Run the command line; returns the exit code (see the module notes)."""
    parser = build_parser()
    try:
        args = parser.parse_args(argv)
    except SystemExit as e:  # argparse has printed the usage error (or the help)
        return e.code if isinstance(e.code, int) else EXIT_USAGE
    from ._data.cells import DataError

    name = f"gyrojax {args.command}"
    try:
        with _signals_raise():
            try:
                code = args.func(args)
                _stop.check()  # a stop whose exception was lost after the last safe point
                return code
            except BaseException as e:
                # After a stop, whatever the exception (ours, or one a library made of it), the signal decides.
                signum = e.signum if isinstance(e, _Interrupted) else _stop.requested()
                if signum is None:
                    raise
                print(f"{name}: stopped by {signal.Signals(signum).name}; the file being written (if any) was "
                      "discarded and its previous version kept", file=sys.stderr)
                if argv is None:  # run as the program: no interpreter teardown in XLA's state after a stop
                    sys.stdout.flush()
                    sys.stderr.flush()
                    os._exit(EXIT_SIGNAL_BASE + signum)
                return EXIT_SIGNAL_BASE + signum
            finally:
                _stop.clear()
    except KeyboardInterrupt:  # outside the main thread, where no handler could be set
        print(f"{name}: interrupted", file=sys.stderr)
        return EXIT_SIGNAL_BASE + signal.SIGINT
    except (DataError, OutputPathError, ValueError) as e:
        print(f"{name}: error: {e}", file=sys.stderr)
        return EXIT_USAGE
    except (FileNotFoundError, IsADirectoryError, NotADirectoryError, PermissionError, FileExistsError) as e:
        print(f"{name}: error: {_os_error_text(e)}", file=sys.stderr)
        return EXIT_USAGE
    except OSError as e:  # the disk is full, an I/O error: nothing the arguments could fix
        print(f"{name}: failed: {_os_error_text(e)}", file=sys.stderr)
        return EXIT_FAILED
    except RuntimeError as e:
        print(f"{name}: failed: {e}", file=sys.stderr)
        return EXIT_FAILED


if __name__ == "__main__":
    sys.exit(main())
