"""The code's structure, measured: package arrows, module sizes, the largest functions.

    python benchmarks/structure.py [--top 5]

Prints
- the import arrows between the four packages (app, worker, web, engine) and between the
  engine's sub-packages, with how many modules make each arrow (from ``ast``, so imports
  inside functions count too, and importlib strings do not: a reader cannot see them either);
- every module over 600 lines, and the largest modules;
- the functions with the highest cyclomatic complexity (radon) and the longest ones.

Aims (issue 24): no module over 600 lines, no function over 80 lines or complexity 20,
arrows app -> worker -> engine and web -> app only.
"""

from __future__ import annotations

import argparse
import ast
from collections import Counter
from pathlib import Path

from radon.complexity import cc_visit

ROOT = Path(__file__).resolve().parent.parent
PACKAGES = ("app", "worker", "web", "engine")


def modules() -> list[Path]:
    return sorted(p for pkg in PACKAGES for p in (ROOT / pkg).rglob("*.py"))


def module_name(path: Path) -> str:
    rel = path.relative_to(ROOT).with_suffix("")
    parts = rel.parts[:-1] if rel.name == "__init__" else rel.parts
    return ".".join(parts)


def imported(tree: ast.AST, name: str, is_package: bool) -> set[str]:
    """Every absolute module name ``tree`` imports (relative imports resolved)."""
    out: set[str] = set()
    for node in ast.walk(tree):
        if isinstance(node, ast.Import):
            out.update(a.name for a in node.names)
        elif isinstance(node, ast.ImportFrom):
            if node.level:
                base = name.split(".")
                base = base[: len(base) - node.level + (1 if is_package else 0)]
                mod = ".".join(base + ([node.module] if node.module else []))
            else:
                mod = node.module or ""
            out.add(mod)
            out.update(f"{mod}.{a.name}" for a in node.names)
    return out


def group(mod: str, depth: int) -> str | None:
    parts = mod.split(".")
    if parts[0] not in PACKAGES:
        return None
    return ".".join(parts[:depth])


def arrows(depth: int, within: str | None = None) -> Counter[tuple[str, str]]:
    """(from, to) -> number of modules of ``from`` importing ``to``, at package ``depth``."""
    known = {module_name(p) for p in modules()}
    counts: Counter[tuple[str, str]] = Counter()
    for path in modules():
        name = module_name(path)
        if within and not name.startswith(within + "."):
            continue
        src = group(name, depth)
        targets = set()
        for mod in imported(ast.parse(path.read_text()), name, path.name == "__init__.py"):
            # keep only names of real modules/packages (not "engine.x.SomeClass")
            while mod and mod not in known:
                mod = mod.rpartition(".")[0]
            dst = group(mod, depth) if mod else None
            if dst and src and dst != src and (not within or dst.startswith(within)):
                targets.add(dst)
        for dst in targets:
            counts[(src, dst)] += 1  # type: ignore[index]
    return counts


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--top", type=int, default=5)
    args = ap.parse_args()

    print("package arrows (modules importing):")
    for (a, b), n in sorted(arrows(1).items()):
        print(f"  {a:>8} -> {b:<8} {n}")
    print("engine sub-package arrows:")
    for (a, b), n in sorted(arrows(2, "engine").items()):
        print(f"  {a:>18} -> {b:<18} {n}")

    sizes = sorted(((len(p.read_text().splitlines()), p) for p in modules()), reverse=True)
    print(f"modules: {len(sizes)}, lines: {sum(n for n, _ in sizes)}, "
          f"over 600 lines: {sum(n > 600 for n, _ in sizes)}")  # fmt: skip
    for n, p in sizes[: max(args.top, sum(n > 600 for n, _ in sizes))]:
        print(f"  {n:5d}  {p.relative_to(ROOT)}")

    funcs = []
    for p in modules():
        for b in cc_visit(p.read_text()):
            for f in [b, *getattr(b, "methods", [])]:
                if f.letter in ("F", "M"):
                    funcs.append((f.complexity, f.endline - f.lineno + 1, f"{p.relative_to(ROOT)}:"
                                  f"{f.fullname}"))  # fmt: skip
    over = sum(c > 20 or n > 80 for c, n, _ in funcs)
    print(f"functions: {len(funcs)}, over complexity 20 or 80 lines: {over}")
    print("  highest complexity:")
    for c, n, name in sorted(funcs, reverse=True)[: args.top]:
        print(f"  cc {c:3d}  {n:4d} lines  {name}")
    print("  longest:")
    for c, n, name in sorted(funcs, key=lambda f: -f[1])[: args.top]:
        print(f"  cc {c:3d}  {n:4d} lines  {name}")


if __name__ == "__main__":
    main()
