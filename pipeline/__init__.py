"""motion's pipeline: one module (or small package) per stage of the data flow.

scene -> timeline -> motion / dynamics -> bake -> farm -> render -> frame_output -> telecine
"""

# motion's version: the one place it is written (pyproject.toml reads it for the package's
# metadata), read here without importlib.metadata, whose parsing costs a rerun 30 ms.
VERSION = "0.1.0"
