"""`cvtbench info`: the backends (available or not, and why), the methods (with their
options, and the plug-ins that could not be loaded, with why) and the versions."""

from __future__ import annotations


def add_parser(sub):
    p = sub.add_parser("info", help="list backends (available, or why not), methods and versions")
    p.add_argument(
        "--recheck",
        action="store_true",
        help="try the OpenCL devices again, forgetting the kept verdicts (each device is tried "
        "once, in a child process, and its verdict kept)",
    )
    p.set_defaults(func=run)


def run(args) -> int:
    from compact_distributions.backends import probe_all
    from compact_distributions.cvt.registry import methods, unavailable_methods

    from ..outputs import versions

    if args.recheck:
        from compact_distributions.backends.opencl import forget_verdicts

        forget_verdicts()
    print("backends:")
    for name, ok, text in probe_all():
        state = "available  " if ok else "unavailable"
        print(f"  {name:<7} {state} {text}")
    records = methods()
    print("methods:", ", ".join(records))
    for m in records.values():
        opts = "".join(f" {o.flag}" for o in m.options)
        print(f"  {m.name:<14} {m.role:<10} {m.summary}" + (f" (options:{opts})" if opts else ""))
    for name, reason in unavailable_methods().items():
        print(f"  {name:<14} unavailable {reason}")
    print("versions:")
    for k, v in versions().items():
        print(f"  {k}: {v}")
    return 0


__all__ = ["add_parser", "run"]
