"""Maps the top-level code folders under the single import root ``mmexec``.

``mmexec.executive`` is ``executive/``, ``mmexec.drivers`` is ``drivers/`` and so on,
for editable and normal installs alike, so no generic name such as ``sim`` lands in
site-packages.  ``mmexec`` itself is an implicit namespace package.
"""
from __future__ import annotations

from pathlib import Path

from setuptools import find_packages, setup

HERE = Path(__file__).parent
FOLDERS = ("executive", "drivers", "skills", "sim", "config", "trees")

packages: list[str] = []
package_dir: dict[str, str] = {}
for folder in FOLDERS:
    for sub in [""] + find_packages(folder):
        name = f"mmexec.{folder}" + (f".{sub}" if sub else "")
        packages.append(name)
        package_dir[name] = folder + ("/" + sub.replace(".", "/") if sub else "")

DATA = ["*.yaml", "*.yml", "*.urdf", "*.pgm", "*.md", "*.png", "*.json", "**/*.yaml", "**/*.urdf", "**/*.pgm",
        # the browser console of `mmexec serve` (executive/serve/static/)
        "static/*.html", "static/*.js", "static/*.css", "static/*.svg", "static/*.png", "static/*.txt"]

setup(
    packages=packages,
    package_dir=package_dir,
    package_data={name: DATA for name in packages},
    include_package_data=True,
)
