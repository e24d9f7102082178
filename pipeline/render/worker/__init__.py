"""A worker's frames: the job loop (render, denoise, header, write), the frame renderer
with its first-frame cache (cold build, warm updates), and the engine's log watch."""
