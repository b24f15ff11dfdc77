"""numba's disk cache is dropped when any source file of the package changes."""

from __future__ import annotations

from pathlib import Path

from nlcx import compiled_cache


def _package(tmp_path: Path) -> Path:
    root = tmp_path / "pkg"
    (root / "sub" / "__pycache__").mkdir(parents=True)
    (root / "a.py").write_text("x = 1\n")
    (root / "sub" / "b.py").write_text("y = 2\n")
    return root


def test_a_changed_callee_module_drops_every_cached_function(tmp_path: Path) -> None:
    root = _package(tmp_path)
    assert compiled_cache.ensure_consistent(root)  # first run: stamped
    cached = [root / "sub" / "__pycache__" / "b.f-1.py311.nbi", root / "sub" / "__pycache__" / "b.f-1.py311.1.nbc"]
    for path in cached:
        path.write_bytes(b"machine code")
    assert not compiled_cache.ensure_consistent(root)  # nothing changed: the cache stays
    assert all(p.exists() for p in cached)
    (root / "a.py").write_text("x = 3\n")  # another module than the cached function's
    assert compiled_cache.ensure_consistent(root)
    assert not any(p.exists() for p in cached)
    assert (root / "__pycache__" / compiled_cache.STAMP.name).read_text().strip() == compiled_cache.source_digest(root)


def test_the_package_is_stamped_with_its_current_source() -> None:
    stamp = compiled_cache.STAMP
    assert stamp.read_text().strip() == compiled_cache.source_digest()
