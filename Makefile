# The two entry points of the README. Both run tools/setup.sh first (idempotent).
.PHONY: setup render test bench

setup:
	@bash tools/setup.sh

render: setup
	.venv/bin/motion render scenes/cannonball.yaml -o out/cannonball

test: setup
	.venv/bin/python -m pytest -q

bench: setup
	.venv/bin/python -m bench
