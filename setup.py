"""Build hook: the wheel carries the repository's ``conf/`` as ``nerif/conf`` so that an installed nerif finds its
configs from any folder (``nerif.configs.config_dir``). Everything else is in ``pyproject.toml``."""
import shutil
from pathlib import Path

from setuptools import setup
from setuptools.command.build_py import build_py


class BuildWithConfigs(build_py):
    def run(self):
        super().run()
        if not self.editable_mode:  # an editable install reads the repository's conf/ in place
            target = Path(self.build_lib) / "nerif" / "conf"
            shutil.rmtree(target, ignore_errors=True)
            shutil.copytree(Path(__file__).parent / "conf", target, ignore=shutil.ignore_patterns("__pycache__"))


setup(cmdclass={"build_py": BuildWithConfigs})
