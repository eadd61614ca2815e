"""Package discovery for the three source folders that install under ``cutkit``.

``cli/`` installs as ``cutkit.cli`` and ``pipelines/`` as ``cutkit.pipelines``
(``package-dir`` in pyproject.toml); no other top-level import name is made.
"""
from setuptools import find_packages, setup

packages = find_packages(include=["cutkit", "cutkit.*"])
packages += ["cutkit.cli"] + ["cutkit.cli." + p for p in find_packages("cli")]
packages += ["cutkit.pipelines"]

setup(packages=packages)
