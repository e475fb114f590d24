"""What the subcommands share: exit codes, output checks and JSON writing, the effects modules, the --model
argument and its device, whole-number options, and the data file with its --fit."""

import argparse
import os
import sys
import warnings

from .._data.io import atomic_write_json, check_output_paths


EXIT_OK, EXIT_FAILED, EXIT_USAGE = 0, 1, 2


def device_names(table) -> tuple[str, ...]:
    """The device names of `table`, for `safe_text`: a name with a newline or an escape is shown escaped."""
    return tuple(dict.fromkeys(table["device"].tolist()))


def na(value, spec: str, reason: str | None = None, unit: str = "") -> str:
    """`value` formatted with `spec` and followed by `unit`, or "n/a" (with the reason) when it is None."""
    if value is None:
        return "n/a" + (f" ({reason})" if reason else "")
    return format(value, spec) + unit


def check_outputs(*outputs) -> None:
    """Check every output path of a command before any work: `(argument, path or None, folder)` triples."""
    check_output_paths(list(outputs))


def load_effects(args) -> None:
    """Register the installed plugins' effects (entry points, once) and those of every --effects-module."""
    from .._effects.plugins import load_effect_entry_points, load_effects_module

    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        load_effect_entry_points()
        for path in getattr(args, "effects_module", None) or ():
            load_effects_module(path)
    for w in caught:
        print(f"gyrojax {args.command}: warning: {w.message}", file=sys.stderr)


def check_finite_effects(effects, gyro) -> None:
    """Refuse, by name, an effect that gives `gyro` NaN or infinite parameters (a user effect's bug: without
    this it surfaces far away, as a failed SVD or an unsettled loop). `effects`: (name, scale) pairs."""
    from .._effects.plugins import nonfinite_effect

    for name, scale in effects:
        why = nonfinite_effect(name, gyro, scale)
        if why is not None:
            raise RuntimeError(f"{why}; an effect must give finite parameters at every size (fix the effect).")


def write_json(obj, path) -> None:
    try:
        atomic_write_json(obj, path)
    except ValueError as e:  # a NaN in a result: a computation that did not give a number, not a usage error
        raise RuntimeError(str(e)) from None


def result_options(parser, what: str) -> None:
    """The options of a command that writes a result: --json FILE, and --out FILE in --format NAME."""
    parser.add_argument("--out", metavar="FILE",
                        help=f"write the {what} here, in the format --format names or else the one of FILE's suffix "
                             "(.json, .md, .txt, or a format registered with gyrojax.io.register_format)")
    parser.add_argument("--format", metavar="NAME",
                        help="the format of --out: json, markdown, text, or a registered one's name")


def check_result_outputs(args, *outputs) -> None:
    """Before any work: --out's format is known (a `ValueError` names the file and the known formats), and every
    output path of the command (--json, --out, then `outputs`) can be written."""
    from .._report import format_for

    if args.format is not None and args.out is None:
        raise ValueError(f"--format {args.format} needs --out FILE: the file to write the result to in that format "
                         "(--json always writes JSON)")
    if args.out is not None:
        format_for(args.out, args.format)
    check_outputs(("--json", args.json, False), ("--out", args.out, False), *outputs)


def write_result_files(args, result) -> None:
    """`result` written to --json (as JSON) and to --out (in its format), each followed by "wrote FILE"."""
    from .._report import write_result

    for path, fmt in ((args.json, "json"), (args.out, args.format)):
        if path:
            try:
                write_result(result, path, fmt)
            except ValueError as e:  # a NaN in a result: a computation that did not give a number
                raise RuntimeError(str(e)) from None
            print(f"wrote {path}")


def model_arg(text):
    """A --model (or simulate's --preset): a preset's name or the path of an existing device file (.toml)."""
    from .._device.file import is_device_file
    from .._presets import PRESETS

    if text in PRESETS:
        return text
    if is_device_file(text):
        if not os.path.isfile(text):
            raise argparse.ArgumentTypeError(f"no device file {text!r} (write one with gyrojax describe --model "
                                             "PRESET --toml FILE.toml)")
        return text
    raise argparse.ArgumentTypeError(f"expected a preset ({', '.join(sorted(PRESETS))}) or a device file FILE.toml, "
                                     f"got {text!r}")


def device_and_free(model: str):
    """The device of a preset or device file, and the file's free parameters (() for a preset)."""
    from .._device.file import is_device_file, read_device_file
    from .._presets import preset

    if is_device_file(model):
        device_file = read_device_file(model)
        return device_file.device, device_file.free
    return preset(model), ()


def positive_int(option):
    def parse(text):
        try:
            value = int(text)
        except ValueError:
            raise argparse.ArgumentTypeError(f"{option} expects a whole number >= 1, got {text!r}") from None
        if value < 1:
            raise argparse.ArgumentTypeError(f"{option} expects a whole number >= 1, got {text!r}")
        return value
    return parse


def table_and_fit(args):
    """The table of the command's data file and the fit of its --fit file (None without one), read after the
    effects are registered (a saved fit may hold a plugin's effect); the fit's warnings go to standard error."""
    from .._data.files import read_table

    load_effects(args)
    table = read_table(args.data)
    fit = None
    if args.fit:
        from .._identify.fitio import load_fit

        with warnings.catch_warnings(record=True) as caught:
            warnings.simplefilter("always")
            fit = load_fit(args.fit)
        for w in caught:
            print(f"gyrojax {args.command}: warning: {w.message}", file=sys.stderr)
    return table, fit


def effects_module_option(parser):
    parser.add_argument("--effects-module", action="append", default=[], metavar="FILE.py",
                        help="import this Python file and register every gyrojax.AbstractEffect subclass it "
                             "defines, for --effect and the diagnosis (repeatable); installed packages' effects "
                             "(entry-point group gyrojax.effects) are loaded too")
