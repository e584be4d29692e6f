"""What setuptools installs: every folder Python would import under navtwin's namespace is a
declared package, with its data files, so set-up prints no "Package would be ignored" warning
and a wheel carries the shipped scenarios, configs and calibrations."""
import fnmatch
import tomllib
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]


def test_every_importable_folder_is_a_package_with_its_data_files():
    tool = tomllib.loads((ROOT / "pyproject.toml").read_text())["tool"]["setuptools"]
    packages, data = set(tool["packages"]), tool.get("package-data", {})
    roots = {name: ROOT / folder for name, folder in tool["package-dir"].items()
             if name.count(".") == 1}  # navtwin.protocols = protocols/, ...
    assert roots
    for name, root in roots.items():
        for folder in [root, *(p for p in root.rglob("*") if p.is_dir())]:
            if folder.name == "__pycache__" or not any(folder.iterdir()):
                continue
            package = ".".join([name, *folder.relative_to(root).parts])
            assert package in packages, f"{folder}: importable as {package}, not declared"
            for f in folder.iterdir():
                if f.is_file() and f.suffix != ".py":
                    assert any(fnmatch.fnmatch(f.name, g) for g in data.get(package, ())), \
                        f"{f}: not in {package}'s package-data"
