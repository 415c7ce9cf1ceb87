"""Ship configs/ (the presets, data only) inside the wheel as torchratslam/presets/."""

from pathlib import Path

from setuptools import setup
from setuptools.command.build_py import build_py

PRESETS = Path(__file__).resolve().parent / "configs"


class BuildWithPresets(build_py):
    """build_py, then copy every preset file into the built package."""

    def run(self) -> None:
        super().run()
        target = Path(self.build_lib) / "torchratslam" / "presets"
        target.mkdir(parents=True, exist_ok=True)
        for f in sorted(PRESETS.iterdir()):
            if f.suffix in (".yaml", ".txt"):
                self.copy_file(str(f), str(target / f.name))


setup(cmdclass={"build_py": BuildWithPresets})
