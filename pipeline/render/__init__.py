"""The renderer: Mitsuba 3 with motion of our own, in rooms by concept (docs/rendering.md):
`poses` (poses over time), `kernel` (the traced kernel), `translate` (scene records to
Mitsuba), `output` (denoising, the temporal pass) and `worker` (the job loop and the
first-frame cache), each importing only the rooms before it."""
