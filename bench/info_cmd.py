"""`cvtbench info`: the backends (available or not, and why), the methods and the versions."""

from __future__ import annotations


def add_parser(sub):
    p = sub.add_parser("info", help="list backends (available, or why not), methods and versions")
    p.set_defaults(func=run)


def run(args) -> int:
    from compact_distributions.backends import probe_all
    from compact_distributions.baselines import method_names

    from .outputs import versions

    print("backends:")
    for name, ok, text in probe_all():
        state = "available  " if ok else "unavailable"
        print(f"  {name:<7} {state} {text}")
    print("methods:", ", ".join(method_names()))
    print("versions:")
    for k, v in versions().items():
        print(f"  {k}: {v}")
    return 0
