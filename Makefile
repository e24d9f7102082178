# The two entry points of the README. Both run tools/setup.sh first (idempotent).
.PHONY: setup render render-cannonball-full render-example showcase-sheets test bench

setup:
	@bash tools/setup.sh

# the showcase shot (3 s, 72 frames at 480x270, denoised) with 24p and 60i movies and a
# contact sheet; under a minute on 2 cores once set up, deliverables included (README)
# (the scene's output.deliver asks for them); motion prints where its frames and deliverables
# are. Run twice, the second run renders and rebuilds nothing. ARGS go last, so
# ARGS="--preset ci-smoke -o out/smoke" replaces the output folder.
render: setup
	.venv/bin/motion render scenes/cannonball-splash.yaml -o out/cannonball-splash $(ARGS)

# the whole 75-second cannonball flight (1,800 frames), by name
render-cannonball-full: setup
	.venv/bin/motion render scenes/cannonball.yaml -o out/cannonball $(ARGS)

# the suite on every core (pytest-xdist; a module's tests stay on one worker, so its shared
# fixtures are made once); ARGS="-n 0" runs it in one process. Tests marked `slow` are left
# out; ARGS="-m slow" runs only them (the later -m wins), as CI's second step does (.ci/run)
test:
	@bash tools/setup.sh --test
	.venv/bin/python -m pytest -q -n auto --dist loadscope -m "not slow" $(ARGS)

bench: setup
	for b in bench/bench_*.py; do echo "== $$b"; .venv/bin/python $$b || exit 1; done

# The imported-character example (docs/imports.md): regenerate the skinned, keyframed glTF
# walker, then render its shot to out/walker/.
render-example: setup
	.venv/bin/python tools/make_walker.py scenes/assets/walker.glb
	.venv/bin/motion render scenes/walker.yaml -o out/walker $(ARGS)

# Contact sheets of every example for docs/showcase/ (docs/showcase.md), rendered by the
# pipeline: a few frames of each scene, small, then `motion contact-sheet`.
showcase-sheets: setup
	.venv/bin/python tools/showcase_sheets.py $(ARGS)
