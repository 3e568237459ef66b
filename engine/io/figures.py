"""Writing a matplotlib figure as PNG: a path that cannot be written is an InvalidInput
with a message a person can read, and the figure is always closed."""

from __future__ import annotations

from pathlib import Path
from typing import Any

from engine.errors import InvalidInput


def save_figure(fig: Any, path: Path, dpi: int) -> None:
    """``fig.savefig(path)`` then close it.

    Raises
    ------
    InvalidInput
        The file cannot be written (no such folder, no permission).
    """
    import matplotlib.pyplot as plt

    try:
        fig.savefig(path, dpi=dpi)
    except OSError as exc:
        raise InvalidInput(f"cannot write plot {path}: {exc.strerror or exc}") from None
    finally:
        plt.close(fig)
