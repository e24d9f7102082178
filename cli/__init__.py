"""Thin click commands: parse options, call the pipeline, turn errors into one line each."""
