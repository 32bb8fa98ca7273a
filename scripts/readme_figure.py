"""Render docs/demo.png from a demo output folder: DEM with break lines, and the mesh."""
import sys
from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402

from floodmesh.core import io  # noqa: E402

out = Path(sys.argv[1] if len(sys.argv) > 1 else "demo_output")
dem = io.read_raster(out / "dem.tif")
nodes, triangles = io.read_mesh_2dm(out / "mesh.2dm")
lines = io.read_lines_gpkg(out / "breaklines.gpkg")
x0, y0, x1, y1 = dem.bounds
ox, oy = x0, y0
gy, gx = np.gradient(dem.values, dem.cell_size)
shade = np.clip(0.5 + 0.6 * (-gx - gy) / np.sqrt(2), 0, 1)

fig, axes = plt.subplots(1, 2, figsize=(13, 5.4))
axes[0].imshow(dem.values, extent=(0, x1 - x0, 0, y1 - y0), cmap="terrain", vmin=15, vmax=25)
axes[0].imshow(shade, extent=(0, x1 - x0, 0, y1 - y0), cmap="gray", alpha=0.35)
axes[0].set_title("Gridded LiDAR (1 m) and traced break lines")
axes[1].tripcolor(nodes[:, 0] - ox, nodes[:, 1] - oy, triangles, nodes[:, 2], cmap="terrain",
                  vmin=15, vmax=25, shading="gouraud")
axes[1].triplot(nodes[:, 0] - ox, nodes[:, 1] - oy, triangles, lw=0.25, color="k")
axes[1].set_title(f"Mesh: {len(nodes)} nodes, {len(triangles)} triangles (≥25°, ≤100 m²)")
for ax in axes:
    for line in lines:
        ax.plot(line[:, 0] - ox, line[:, 1] - oy, color="#d62828", lw=0.9)
    ax.set_aspect("equal")
    ax.set_xlim(0, x1 - x0)
    ax.set_ylim(0, y1 - y0)
    ax.set_xlabel("m")
fig.tight_layout()
fig.savefig("docs/demo.png", dpi=72)
# a 128-colour palette keeps the picture small in the repository
from PIL import Image  # noqa: E402

Image.open("docs/demo.png").convert("RGB").quantize(128).save("docs/demo.png", optimize=True)
