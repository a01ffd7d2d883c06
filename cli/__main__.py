from cli.main import main

# Spawned session workers import this module as __mp_main__: only run the CLI as a script.
if __name__ == "__main__":
    raise SystemExit(main())
