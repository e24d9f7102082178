"""Poses over time, in one home: the renderer's view of a baked frame (`stacked`: every
track as [frame time, N shutter samples]), poses at one instant or across the shutter on
the host (`shutter`, numpy), and poses at each path's own time in the kernel (`kernel`,
drjit: the per-frame array, lerp and slerp between baked samples, rest-frame maps)."""
