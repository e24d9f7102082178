# The two entry points of the README. Both run tools/setup.sh first (idempotent).
.PHONY: setup render render-cannonball-full render-example test bench

setup:
	@bash tools/setup.sh

render: setup
	.venv/bin/motion render scenes/cannonball.yaml -o out/cannonball $(ARGS)

# the whole 75-second cannonball flight (1,800 frames), by name
render-cannonball-full: setup
	.venv/bin/motion render scenes/cannonball.yaml -o out/cannonball $(ARGS)

test: setup
	.venv/bin/python -m pytest -q $(ARGS)

bench: setup
	for b in bench/bench_*.py; do echo "== $$b"; .venv/bin/python $$b || exit 1; done

# The imported-character example (docs/imports.md): regenerate the skinned, keyframed glTF
# walker, then render its shot to out/walker/.
render-example: setup
	.venv/bin/python tools/make_walker.py scenes/assets/walker.glb
	.venv/bin/motion render scenes/walker.yaml -o out/walker $(ARGS)
