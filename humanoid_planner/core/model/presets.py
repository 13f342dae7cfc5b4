"""Built-in robot presets: name → config/robots/<name>.urdf/.srdf.

The files are generated from the papers' D-H tables by scripts/gen_presets.py and committed; this
module only finds them: in the source tree (running from a checkout or an editable install), or in
the share/humanoid_planner folder that an install (pip, colcon, `setup.py install`) puts beside the
package it installs, found from where this module lies, so the installed copy reads its own data.
"""
from __future__ import annotations

import sys
from pathlib import Path
from typing import Iterator

PRESET_NAMES: tuple[str, ...] = ("armar3", "dual_arm", "maru1")
PACKAGE = "humanoid_planner"
_REL = Path("config") / "robots"


class UnknownPreset(KeyError):
    """The name is not one of PRESET_NAMES."""


def _candidate_dirs() -> Iterator[Path]:
    """Folders that may hold the presets, the copy that belongs to this module first (lazy: ament is
    asked only if needed)."""
    package = Path(__file__).resolve().parents[2]
    yield package.parent / _REL  # source checkout: <repo>/config/robots
    # installed: data_files go to <prefix>/share/<package>, the package to <prefix>/lib/pythonX.Y/
    # site-packages (3 levels up: prefix) or, with `pip install --target`, beside the package (0 up)
    for level in list(package.parents)[:4]:
        yield level / "share" / PACKAGE / _REL
    try:  # a sourced ROS 2 workspace whose share folder lies elsewhere
        from ament_index_python.packages import get_package_share_directory

        yield Path(get_package_share_directory(PACKAGE)) / _REL
    except Exception:  # not installed, no AMENT_PREFIX_PATH, package not in the index
        pass
    for prefix in dict.fromkeys((sys.prefix, sys.base_prefix)):  # pip install into a venv / system
        yield Path(prefix) / "share" / PACKAGE / _REL


def preset_dir(name: str) -> Path:
    """The first folder holding both files of preset `name`."""
    if name not in PRESET_NAMES:
        raise UnknownPreset(f"unknown robot preset {name!r}; known: {', '.join(PRESET_NAMES)}")
    searched = []
    for d in _candidate_dirs():
        if (d / f"{name}.urdf").is_file() and (d / f"{name}.srdf").is_file():
            return d
        searched.append(str(d))
    raise FileNotFoundError(f"preset {name!r} not found; searched: {'; '.join(searched)}")


def preset_paths(name: str) -> tuple[Path, Path]:
    """(URDF path, SRDF path) of a built-in preset."""
    d = preset_dir(name)
    return d / f"{name}.urdf", d / f"{name}.srdf"
