"""Thin click commands: parse options, call the pipeline, turn errors into one line each."""


def start() -> None:
    """The `motion` console script: `main.main` with the cyclic garbage collector off from
    before click is imported (cli/main.py says why, and when it comes back on)."""
    import gc

    enabled = gc.isenabled()
    gc.disable()
    from . import main

    main.main(gc_was_enabled=enabled)
