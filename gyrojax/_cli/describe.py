"""`gyrojax describe`: every leaf of a device, or the device written as a device file."""


from .common import EXIT_OK, check_outputs, model_arg, write_json


def handle(args):
    from .._describe import describe, describe_text

    check_outputs(("--json", args.json, False), ("--toml", args.toml, False))
    records = describe(args.model)
    print(describe_text(records))
    if args.json:
        write_json([r.to_json() for r in records], args.json)
        print(f"wrote {args.json}")
    if args.toml:
        from .._describe import write_toml

        write_toml(args.model, args.toml)
        print(f"wrote {args.toml}: edit it and give it back as --model {args.toml}")
    return EXIT_OK


def add_parser(sub) -> None:
    """`gyrojax describe`: every leaf of a device."""
    desc = sub.add_parser("describe", help="every leaf of a device (a preset or a device file): its path, value, "
                                           "unit and provenance; --toml writes it as a device file",
                          description="List every leaf of the device (the path an effect reads or writes, e.g. "
                                      "vcf_electrode.force_per_volt2), with its value, unit, description and where "
                                      "the preset (or the device file) took it from (docs/adding_an_effect.md); "
                                      "--toml writes it as a device file to edit (docs/own_device.md).")
    desc.add_argument("--model", type=model_arg, default="paper-qmg",
                      help="the preset or device file FILE.toml to describe (default paper-qmg)")
    desc.add_argument("--json", help="write the records (path, value, unit, description, provenance) as JSON here")
    desc.add_argument("--toml", metavar="OUT.toml",
                      help="write the device as a device file here, to edit and give back as --model OUT.toml "
                           "(docs/own_device.md)")
    desc.set_defaults(func=handle)
