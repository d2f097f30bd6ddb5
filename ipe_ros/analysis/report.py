"""A report: its parameters, results (JSON-ready), Markdown text and figures, written side by side."""

from __future__ import annotations

import json
import math
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np


def _jsonable(value: Any) -> Any:
    if isinstance(value, dict):
        return {str(k): _jsonable(v) for k, v in value.items()}
    if isinstance(value, (list, tuple)):
        return [_jsonable(v) for v in value]
    if hasattr(value, "to_dict"):
        return _jsonable(value.to_dict())
    if isinstance(value, np.ndarray):
        return _jsonable(value.tolist())
    if isinstance(value, (np.floating, float)):
        v = float(value)
        return v if math.isfinite(v) else None  # JSON has no NaN/inf; null means "undefined"
    if isinstance(value, np.integer):
        return int(value)
    if isinstance(value, Path):
        return str(value)
    return value


@dataclass
class Report:
    """``name`` names the files: NAME.json, NAME.md and NAME_*.png in the output folder."""

    name: str
    title: str
    parameters: dict[str, Any]
    results: dict[str, Any] = field(default_factory=dict)
    lines: list[str] = field(default_factory=list)
    figures: list[str] = field(default_factory=list)

    def add(self, *lines: str) -> None:
        self.lines.extend(lines)

    def table(self, header: list[str], rows: list[list[Any]]) -> None:
        def cell(v: Any) -> str:
            if isinstance(v, float):
                return "-" if not math.isfinite(v) else f"{v:.3f}"
            return str(v).replace("|", "\\|")  # a bare | would end the cell
        self.lines.append("| " + " | ".join(cell(h) for h in header) + " |")
        self.lines.append("|" + "---|" * len(header))
        for row in rows:
            self.lines.append("| " + " | ".join(cell(v) for v in row) + " |")
        self.lines.append("")

    def figure(self, fig, out_dir: Path, suffix: str, caption: str) -> None:
        out_dir.mkdir(parents=True, exist_ok=True)
        path = out_dir / f"{self.name}_{suffix}.png"
        fig.savefig(path, dpi=110, bbox_inches="tight")
        import matplotlib.pyplot as plt
        plt.close(fig)
        self.figures.append(path.name)
        self.lines += [f"![{caption}]({path.name})", ""]

    def write(self, out_dir: Path) -> tuple[Path, Path]:
        out_dir.mkdir(parents=True, exist_ok=True)
        json_path, md_path = out_dir / f"{self.name}.json", out_dir / f"{self.name}.md"
        json_path.write_text(json.dumps(_jsonable({"experiment": self.name, "title": self.title,
                                                   "parameters": self.parameters, "results": self.results,
                                                   "figures": self.figures}), indent=1) + "\n")
        parameters = ", ".join(f"{k} = {v}" for k, v in self.parameters.items())
        md_path.write_text(f"# {self.title}\n\nParameters: {parameters}.\n\n" + "\n".join(self.lines) + "\n")
        return json_path, md_path


def pyplot():
    """matplotlib with a file-only backend (never a window)."""
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    return plt
