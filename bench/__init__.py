"""Running methods on problems, evaluating them, and the `cvtbench` command line."""
