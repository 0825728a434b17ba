"""Package layout for setuptools; everything else is in pyproject.toml.

``configs/`` stays at the top of the repository and is mapped into the wheel as the data
package ``bound_env.configs`` (gaits and controller specs in its subpackages ``gaits`` and
``controllers``; read with importlib.resources, see `bound_env.files.resources`). The
code packages are found, so a new subpackage under ``bound_env/`` or ``agents/`` is shipped
without editing this file. The shipped policies are package data of ``agents``
(``agents/policies/<name>/`` and ``agents/policies/<group>/<name>/``, see
``[tool.setuptools.package-data]``).
"""

from setuptools import find_packages, setup

setup(
    packages=find_packages(include=["bound_env", "bound_env.*", "agents", "agents.*"])
    + ["bound_env.configs", "bound_env.configs.gaits", "bound_env.configs.controllers"],
    package_dir={
        "bound_env.configs": "configs",
        "bound_env.configs.gaits": "configs/gaits",
        "bound_env.configs.controllers": "configs/controllers",
    },
)
