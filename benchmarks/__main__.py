"""Run every benchmark in this folder, one after the other."""

import importlib
import pkgutil

import benchmarks

for info in sorted(pkgutil.iter_modules(benchmarks.__path__), key=lambda i: i.name):
    if info.name.startswith("bench_"):
        print(f"\n=== {info.name} ===", flush=True)
        importlib.import_module(f"benchmarks.{info.name}").main()
