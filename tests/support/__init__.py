"""Reference implementations and helpers the tests (and benchmarks) share."""
