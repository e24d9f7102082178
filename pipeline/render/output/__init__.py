"""What happens to a rendered frame's pixels after the kernel: OIDN denoising, and the
temporal pass over an output folder's neighbouring frames."""
