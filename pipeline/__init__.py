"""motion's pipeline: one module (or small package) per stage of the data flow.

scene -> timeline -> motion / dynamics -> bake -> farm -> render -> frame_output -> telecine
"""
