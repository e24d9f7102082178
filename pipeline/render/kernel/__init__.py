"""What runs in the traced kernel: the `motion_path` integrator, the scene a path meets at
its time (the static set, and the one traversal of everything that moves through the
broadphase and the atlas), light sampling, the deterministic film, the AOV table and the
shared SBT owner."""
