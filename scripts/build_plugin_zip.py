"""Build dist/floodmesh-VERSION.zip, the plugin as QGIS's plugin manager installs it: the tracked
plugin files under a top-level floodmesh/ folder."""
import configparser
import subprocess
import sys
import zipfile
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
PLUGIN_PARTS = ("metadata.txt", "__init__.py", "LICENSE", "README.md", "provider/",
                "algorithms/", "core/", "icons/", "models/", "docs/")


def build(out_dir: Path = ROOT / "dist") -> Path:
    meta = configparser.ConfigParser()
    meta.read(ROOT / "metadata.txt")
    version = meta["general"]["version"]
    tracked = subprocess.run(["git", "ls-files"], cwd=ROOT, capture_output=True, text=True,
                             check=True).stdout.split()
    files = [f for f in tracked if f.startswith(PLUGIN_PARTS) or f in PLUGIN_PARTS]
    out_dir.mkdir(parents=True, exist_ok=True)
    target = out_dir / f"floodmesh-{version}.zip"
    with zipfile.ZipFile(target, "w", zipfile.ZIP_DEFLATED) as archive:
        for name in sorted(files):
            archive.write(ROOT / name, f"floodmesh/{name}")
    return target


if __name__ == "__main__":
    path = build(Path(sys.argv[1]) if len(sys.argv) > 1 else ROOT / "dist")
    print(f"written {path}")
