"""What the figure scripts of bench/ share: writing a figure where the docs link it."""

from __future__ import annotations

from pathlib import Path


def save(fig, out: Path, dpi: int = 120) -> None:
    """Lay out ``fig`` and write it to ``out`` (its folder made if needed), saying where."""
    fig.tight_layout()
    out.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(out, dpi=dpi)
    print(f"wrote {out}")
