"""Speed measurements. Each `bench_*.py` module has a `main()`; run one with
`python -m benchmarks.bench_NAME`, or all of them with `python -m benchmarks`."""
