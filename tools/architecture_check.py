"""The architecture's rules, checked: no import loop between modules, no import from a
lower stage to a higher one, and public definitions with docstrings.

    python tools/architecture_check.py          # prints violations, exits 1 if any

Every import counts, also those inside functions (a lazy import is still a dependency).
The stages, lowest first, are STAGES below; a module may import its own stage and lower
ones. tests/project/test_architecture.py runs this check.
"""
from __future__ import annotations

import ast
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
PACKAGE = "motion"
# package folder -> import prefix (pyproject maps pipeline/ to motion.pipeline, cli/ to motion.cli)
FOLDERS = {"pipeline": f"{PACKAGE}.pipeline", "cli": f"{PACKAGE}.cli"}

# Stages, lowest first. A module belongs to the longest prefix listed here.
STAGES: list[tuple[str, ...]] = [
    ("motion.pipeline", "motion.pipeline.errors", "motion.pipeline.limits", "motion.pipeline.write_policy", "motion.pipeline.cache", "motion.pipeline.count_bar", "motion.pipeline.lazy"),
    ("motion.pipeline.timeline", "motion.pipeline.meshes", "motion.pipeline.images", "motion.pipeline.expr", "motion.pipeline.geometry", "motion.pipeline.field_model", "motion.pipeline.deliverables"),
    ("motion.pipeline.scene",),
    ("motion.pipeline.motion",),  # evaluation takes a simulation's records as arguments, never imports dynamics
    ("motion.pipeline.dynamics",),  # simulates on top of motion's poses and keyframes
    ("motion.pipeline.bake",),
    ("motion.pipeline.variant", "motion.pipeline.presets", "motion.pipeline.frame_output", "motion.pipeline.identity"),  # identity reads frame headers; the renderer gives it its sorting of the scene
    # the renderer's rooms (docs/rendering.md), each importing only the rooms before it
    ("motion.pipeline.render", "motion.pipeline.render.poses"),  # poses over time: host and kernel
    ("motion.pipeline.render.kernel",),  # the traced kernel: integrator, traversal, lights, film
    ("motion.pipeline.render.translate",),  # scene records to Mitsuba: roles, shapes, assets, deforming templates
    ("motion.pipeline.render.output",),  # denoising and the temporal pass
    ("motion.pipeline.render.worker",),  # the job loop and the first-frame cache
    ("motion.pipeline.telecine", "motion.pipeline.compare"),  # compare reads frames, makes its report images through telecine's view
    ("motion.pipeline.farm",),
    ("motion.pipeline.shot",),
    ("motion.cli",),
]


def modules() -> dict[str, Path]:
    """Every module of the package by dotted name."""
    out: dict[str, Path] = {}
    for folder, prefix in FOLDERS.items():
        for path in sorted((ROOT / folder).rglob("*.py")):
            rel = path.relative_to(ROOT / folder).with_suffix("")
            parts = [p for p in rel.parts if p != "__init__"]
            out[".".join([prefix, *parts])] = path
    return out


def imports(name: str, path: Path, known: set[str]) -> set[str]:
    """The package modules `name` imports (absolute or relative, at any depth)."""
    tree = ast.parse(path.read_text(), str(path))
    is_pkg = path.name == "__init__.py"
    base = name.split(".") if is_pkg else name.split(".")[:-1]
    found: set[str] = set()

    def resolve(mod: str) -> str | None:
        while mod and mod not in known:
            mod = mod.rpartition(".")[0]
        return mod or None

    for node in ast.walk(tree):
        if isinstance(node, ast.Import):
            for alias in node.names:
                if alias.name.startswith(PACKAGE + "."):
                    if (m := resolve(alias.name)) is not None:
                        found.add(m)
        elif isinstance(node, ast.ImportFrom):
            if node.level:
                anchor = base[: len(base) - node.level + 1]
                mod = ".".join(anchor + ([node.module] if node.module else []))
            else:
                mod = node.module or ""
                if not mod.startswith(PACKAGE + "."):
                    continue
            for alias in node.names:
                full = f"{mod}.{alias.name}"
                m = full if full in known else resolve(mod)
                if m is not None:
                    found.add(m)
    found.discard(name)
    return found


def stage(name: str) -> int:
    """The stage index of a module (its longest listed prefix)."""
    best, rank = -1, 0
    for i, prefixes in enumerate(STAGES):
        for p in prefixes:
            if (name == p or name.startswith(p + ".")) and len(p) > best:
                best, rank = len(p), i
    return rank


def cycles(graph: dict[str, set[str]]) -> list[list[str]]:
    """Strongly connected components with more than one module (Tarjan)."""
    index: dict[str, int] = {}
    low: dict[str, int] = {}
    stack: list[str] = []
    on: set[str] = set()
    out: list[list[str]] = []
    counter = [0]

    def visit(v: str) -> None:
        index[v] = low[v] = counter[0]
        counter[0] += 1
        stack.append(v)
        on.add(v)
        for w in sorted(graph[v]):
            if w not in index:
                visit(w)
                low[v] = min(low[v], low[w])
            elif w in on:
                low[v] = min(low[v], index[w])
        if low[v] == index[v]:
            comp = []
            while True:
                w = stack.pop()
                on.discard(w)
                comp.append(w)
                if w == v:
                    break
            if len(comp) > 1:
                out.append(sorted(comp))

    sys.setrecursionlimit(10000)
    for v in sorted(graph):
        if v not in index:
            visit(v)
    return out


def undocumented(path: Path) -> list[str]:
    """Public module-level functions and classes, and public methods, without a docstring."""
    tree = ast.parse(path.read_text(), str(path))
    missing = []
    for node in tree.body:
        if isinstance(node, (ast.FunctionDef, ast.AsyncFunctionDef, ast.ClassDef)) and not node.name.startswith("_"):
            if ast.get_docstring(node) is None:
                missing.append(f"{path.relative_to(ROOT)}:{node.lineno}: {node.name}")
            if isinstance(node, ast.ClassDef):
                for sub in node.body:
                    if isinstance(sub, (ast.FunctionDef, ast.AsyncFunctionDef)) and not sub.name.startswith("_") and ast.get_docstring(sub) is None:
                        missing.append(f"{path.relative_to(ROOT)}:{sub.lineno}: {node.name}.{sub.name}")
    return missing


def problems() -> list[str]:
    """Every violation, one line each."""
    mods = modules()
    known = set(mods)
    graph = {m: imports(m, p, known) for m, p in mods.items()}
    out = [f"import loop: {' <-> '.join(c)}" for c in cycles(graph)]
    for m, deps in sorted(graph.items()):
        for d in sorted(deps):
            if stage(d) > stage(m):
                out.append(f"upward import: {m} (stage {stage(m)}) imports {d} (stage {stage(d)})")
    for p in mods.values():
        out += [f"no docstring: {x}" for x in undocumented(p)]
    return out


def main() -> int:
    found = problems()
    for line in found:
        print(line)
    kinds: dict[str, int] = {}
    for line in found:
        kinds[line.split(":")[0]] = kinds.get(line.split(":")[0], 0) + 1
    print(f"{len(found)} problem(s): " + (", ".join(f"{v} {k}" for k, v in sorted(kinds.items())) or "none"))
    return 1 if found else 0


if __name__ == "__main__":
    raise SystemExit(main())
