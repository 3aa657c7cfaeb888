"""The ``cvtbench`` commands, one module each: parse the options, build the command's
typed request, call the library (:mod:`compact_distributions.bench`).  :mod:`.cli` is
the entry point that dispatches to them."""
