"""Terrain fidelity per node: FloodMesh's chain against a uniform 25° mesh and pydelatin on
analytic floodplains whose true surface and true break lines are known.

    nice .venv/bin/python benchmarks/fidelity.py [--quick] [--chains landed,default,no-join,no-spacing]
        [--terrains …] [--noise …] [--density …] [--real]

For each terrain of the corpus (``benchmarks/corpus.py``: the demo's geometry with a seed it
never saw, an oblique one, lines at every angle to the grid, crossings and a junction, narrow
embankments; ``--terrains``), noise (``--noise``, 5 and 15 cm by default) and density
(``--density``, 9 and 2 ground points/m²), the whole chain (``run_pipeline``, reference-case
options) runs once per chain of options; its mesh is scored against the TRUE surface (RMSE over 100,000 random points)
and its break lines against the true ones (recall, precision within 2 m, pieces per true line,
where the pieces of each true line meet: junction or crossing, mid-run, second line in the band;
recall and pieces per feature; the median crest height of each levee, road or embankment
against the true one, which a flood's overtopping follows)
and the whole segments the PSLG left out for the angle bound and the line ends snapped onto
another line (T-junctions) are counted.
Peers, in the same run: uniform 25° Triangle meshes without break lines whose nodes carry the
exact elevation (the node count at FloodMesh's RMSE interpolated in log-log), and pydelatin
(greedy TIN, no angle bound) on the same DEM. Ratios are uniform nodes / FloodMesh nodes at the
same true RMSE; pydelatin's "never" means no error bound brings its mesh of the noisy DEM down
to FloodMesh's true RMSE. Bars (issue 18, reference case): ≥ 15x, < 2 pieces, recall and
precision ≥ 0.95. ``--real`` adds the real samples of ../shared/data/real, which have no true
surface or lines: scored on a tenth of their points held out, against uniform meshes with the
DEM's z on the same points (``--terrains none --real``: those alone).
"""
from __future__ import annotations

import argparse
import re
import sys
import tempfile
import time
from pathlib import Path

import numpy as np
import shapely
from pyproj import CRS

sys.path.insert(0, str(Path(__file__).resolve().parent.parent.parent))
sys.path.insert(0, str(Path(__file__).resolve().parent))

from corpus import TERRAINS  # noqa: E402  (benchmarks/corpus.py)
from floodmesh.core.frontends import demo
from floodmesh.core import io  # noqa: E402
from floodmesh.core.steps.accuracy import tin_elevation  # noqa: E402
from floodmesh.core.steps.mesh import Mesh, build_mesh  # noqa: E402
from floodmesh.core.options import RunOptions  # noqa: E402
from floodmesh.core.chain.pipeline import run_pipeline  # noqa: E402
from floodmesh.core.steps.validation import score_breaklines  # noqa: E402

# option sets of the chain: "landed" is the chain before issue 18's steps (no localisation, node
# z from the DEM, conforming Delaunay), "default" today's
CHAINS = {
    "landed": dict(localise=False, node_elevation="dem", conforming=True, min_spacing=0,
                   flow_area=0),
    "default": dict(),                        # with issue 16's line spacing and flow area
    "no-flow-area": dict(flow_area=0),        # the default chain before the flow area
    "no-spacing": dict(min_spacing=0),        # the terrain fits alone
    "no-join": dict(join_gap=0),              # localised pieces left unjoined
    "conforming": dict(conforming=True),     # today's chain with Triangle's switch D
    "far-field": dict(far_field_area=400.0),  # today's chain, up to 400 m² where plane
    "spacing-2": dict(min_spacing=2.0),      # lines and corners kept 2 m (α·Δ) apart, not d
}
UNIFORM_AREAS = (50, 20, 10, 5, 2.5, 1.2, 0.6, 0.3)
DELATIN_ERRORS = (0.6, 0.4, 0.25, 0.15, 0.1, 0.07, 0.05)


def true_rmse(mesh: Mesh, floodplain, sample: np.ndarray, truth: np.ndarray) -> float:
    z = tin_elevation(mesh, sample[:, 0], sample[:, 1])
    return float(np.sqrt(np.nanmean((z - truth) ** 2)))


def nodes_at(rmse: float, curve, extrapolate: bool = True) -> float:
    """Nodes a curve of (nodes, rmse) needs for ``rmse``, interpolated (or extrapolated from
    the last two) in log-log; NaN below the curve's least RMSE without ``extrapolate``."""
    nodes, errors = np.log([c[0] for c in curve]), np.log([c[1] for c in curve])
    order = np.argsort(errors)
    nodes, errors = nodes[order], errors[order]
    x = np.log(rmse)
    if x < errors[0] and not extrapolate:
        return float("nan")
    if x < errors[0]:  # finer than the finest mesh: extend its last step
        slope = (nodes[1] - nodes[0]) / (errors[1] - errors[0])
        return float(np.exp(nodes[0] + slope * (x - errors[0])))
    return float(np.exp(np.interp(x, errors, nodes)))


def uniform_curve(dem, floodplain, sample, truth):
    curve = []
    for area in UNIFORM_AREAS:
        mesh = build_mesh(dem, [], min_angle=25, max_area=area)
        local = mesh.nodes[:, :2] - demo.DEMO_ORIGIN
        exact = Mesh(np.column_stack([mesh.nodes[:, :2], demo.ground_elevation(
            local[:, 0], local[:, 1], floodplain)]), mesh.triangles, mesh.crs)
        curve.append((len(mesh.nodes), true_rmse(exact, floodplain, sample, truth)))
    return curve


def delatin_curve(dem, floodplain, sample, truth):
    try:
        from pydelatin import Delatin
    except ImportError:
        return None
    z = np.where(np.isfinite(dem.values), dem.values, np.nanmean(dem.values)).astype(np.float32)
    curve = []
    for error in DELATIN_ERRORS:
        tin = Delatin(z, width=dem.shape[1], height=dem.shape[0], max_error=error)
        vx, vy = dem.cell_centres(dem.shape[0] - 1 - tin.vertices[:, 1], tin.vertices[:, 0])
        mesh = Mesh(np.column_stack([vx, vy, tin.vertices[:, 2]]),
                    tin.triangles.astype(np.int64), dem.crs)
        curve.append((len(mesh.nodes), true_rmse(mesh, floodplain, sample, truth)))
    return curve


def crest_heights(mesh: Mesh, floodplain, spacing: float = 2.0, margin: float = 15.0) -> dict:
    """Per raised feature (a levee, road or embankment), the median over cross-sections every
    ``spacing`` m of the mesh's highest z across its crest less the true crest's (m): what a
    flood model's overtopping follows. Sections within ``margin`` m of the area's edge, off the
    mesh, or where another feature stands higher (a crossing) are left out."""
    inside = shapely.box(margin, margin, demo.WIDTH - margin, demo.HEIGHT - margin)
    errors = {}
    for name, (line, profile) in floodplain.features.items():
        if profile.height <= 0:
            continue
        centre = shapely.intersection(line, inside)
        runs = [g for g in getattr(centre, "geoms", [centre]) if not g.is_empty]
        across = np.linspace(-profile.half_top - 1.0, profile.half_top + 1.0, 81)
        heights = []
        for run in runs:
            at = np.arange(spacing, run.length - spacing, spacing)
            if not len(at):
                continue
            xy = shapely.get_coordinates(run.interpolate(at))
            ahead = shapely.get_coordinates(run.interpolate(np.minimum(at + 0.01, run.length)))
            tangent = (ahead - xy) / np.linalg.norm(ahead - xy, axis=1)[:, None]
            normal = np.column_stack([-tangent[:, 1], tangent[:, 0]])
            section = xy[:, None, :] + across[None, :, None] * normal[:, None, :]
            x, y = section[..., 0].ravel(), section[..., 1].ravel()
            true = demo.ground_elevation(x, y, floodplain).reshape(section.shape[:2])
            ours = tin_elevation(mesh, x + demo.DEMO_ORIGIN[0],
                                 y + demo.DEMO_ORIGIN[1]).reshape(section.shape[:2])
            crest = np.abs(true.max(axis=1) - true[:, len(across) // 2]) < 0.01
            keep = crest & np.isfinite(ours).all(axis=1)
            heights.append(ours[keep].max(axis=1) - true[keep].max(axis=1))
        if heights and sum(map(len, heights)):
            errors[name] = float(np.median(np.concatenate(heights)))
    return errors


def feature_of_lines(floodplain) -> list:
    """The feature (its name, or "terrace") of each of ``demo.true_breaklines``' lines."""
    area = shapely.box(0, 0, demo.WIDTH, demo.HEIGHT)
    names = [name for name, (line, profile) in floodplain.features.items()
             for r in profile.break_offsets for side in (r, -r)
             if not shapely.intersection(line.offset_curve(side), area).is_empty]
    return names + ["terrace"] * (2 if floodplain.terrace is not None else 0)


def breaks(reference, features, spans) -> dict:
    """Where the pieces of each true line (``score_breaklines``'s ``spans_m``) meet: at a
    junction or crossing (the gap within 8 m of another feature's line), mid-run, or a second
    line beside the first in the same band (overlapping along the true line)."""
    kinds = {"junction": 0, "mid-run": 0, "second line": 0}
    for i, ref in enumerate(reference):
        others = shapely.union_all([r for r, f in zip(reference, features) if f != features[i]])
        for (_, a1), (b0, _) in zip(spans[i][:-1], spans[i][1:]):
            if b0 < a1 - 1.0:
                kinds["second line"] += 1
            elif ref.interpolate(0.5 * (a1 + b0)).distance(others) < 8 + 0.5 * (b0 - a1):
                kinds["junction"] += 1
            else:
                kinds["mid-run"] += 1
    return kinds


def run_case(name, floodplain, seed, noise, density, chains, work: Path):
    points, classes = demo.synthetic_floodplain(density=density, noise=noise, seed=seed,
                                                floodplain=floodplain)
    source = work / "points.laz"
    io.write_points_las(source, points, classes=classes)
    rng = np.random.default_rng(seed + 1000)
    local = np.column_stack([rng.uniform(2, demo.WIDTH - 2, 100_000),
                             rng.uniform(2, demo.HEIGHT - 2, 100_000)])
    truth = demo.ground_elevation(local[:, 0], local[:, 1], floodplain)
    sample = local + demo.DEMO_ORIGIN
    reference = [shapely.affinity.translate(g, *demo.DEMO_ORIGIN)
                 for g in demo.true_breaklines(floodplain)]
    rows, dem = [], None
    for chain in chains:
        out = work / chain
        start = time.perf_counter()
        report = run_pipeline(source, out, RunOptions(**CHAINS[chain]))
        seconds = time.perf_counter() - start
        nodes, triangles = io.read_mesh_2dm(out / "mesh.2dm")
        mesh = Mesh(nodes, triangles, points.crs)
        traced = io.read_lines_gpkg(out / "breaklines.gpkg")
        score = score_breaklines(traced, reference, 2.0)
        features = feature_of_lines(floodplain)
        score["breaks"] = breaks(reference, features, score["spans_m"])
        mine = {f: np.array([g == f for g in features]) for f in dict.fromkeys(features)}
        score["features"] = {f: (float(np.sum(np.array(score["recalled_m"])[m])
                                       / np.sum(np.array(score["lengths_m"])[m])),
                                 float(np.mean(np.array(score["pieces"])[m])))
                             for f, m in mine.items()}
        # whole break-line segments the PSLG left out for the angle bound (see build_pslg)
        score["t_junctions"] = report["terrain_fit"].get("t_junctions_snapped", 0)
        score["dropped"] = sum(int(m) for n in report["notes"]
                               for m in re.findall(r"\((\d+) too short were left out\)", n))
        score["crest_m"] = crest_heights(mesh, floodplain)
        score["cfl"] = report["hydraulics"]["cfl_slowdown_vs_uniform"]
        score["min_inradius"] = report["hydraulics"]["min_inradius_m"]
        rows.append((chain, len(nodes), true_rmse(mesh, floodplain, sample, truth), score,
                     report["min_angle_deg"], seconds))
        dem = io.read_raster(out / "dem.tif")
    uniform = uniform_curve(dem, floodplain, sample, truth)
    delatin = delatin_curve(dem, floodplain, sample, truth)
    print(f"\n## {name}, {density:g} points/m², {100 * noise:g} cm noise")
    print(f"{'chain':<10}{'nodes':>8}{'true RMSE cm':>14}{'uniform/ours':>14}"
          f"{'delatin/ours':>14}{'recall':>8}{'precision':>10}{'pieces':>8}{'min angle':>11}"
          f"{'CFL':>6}{'s':>6}  breaks (junction/mid-run/second line)")
    results = []
    for chain, n, rmse, score, angle, seconds in rows:
        ratio = nodes_at(rmse, uniform) / n
        peer = nodes_at(rmse, delatin, extrapolate=False) / n if delatin else np.nan
        peer = (f"{peer:>14.1f}" if np.isfinite(peer) else f"{'never':>14}" if delatin
                else f"{'n/a':>14}")  # n/a: pydelatin not installed (make bench installs it)
        print(f"{chain:<10}{n:>8,}{100 * rmse:>14.2f}{ratio:>13.1f}x{peer}"
              f"{score['recall']:>8.3f}{score['precision']:>10.3f}{score['mean_pieces']:>8.2f}"
              f"{angle:>10.1f}°{score['cfl']:>6.1f}{seconds:>6.0f}  {'/'.join(map(str, score['breaks'].values()))}")
        results.append((chain, ratio, score))
    for chain, n, rmse, score, angle, seconds in rows:
        print(f"{chain}, per feature (recall, pieces per true line): " + "; ".join(
            f"{f} {r:.2f}, {p:.1f}" for f, (r, p) in score["features"].items()))
        if score["crest_m"]:
            print(f"{chain}, crest height, mesh less true (median, cm): " + "; ".join(
                f"{f} {100 * e:+.1f}" for f, e in score["crest_m"].items()))
    print("uniform 25° (exact z): " + ", ".join(f"{n:,} nodes {100 * r:.2f} cm"
                                                for n, r in uniform[2::2]))
    if delatin:
        print("pydelatin (DEM):       " + ", ".join(f"{n:,} nodes {100 * r:.2f} cm"
                                                    for n, r in delatin[1::2]))
    return results


REAL = Path(__file__).resolve().parents[1].parent / "shared" / "data" / "real"
REAL_HOLDOUT = 0.1  # a tenth of a real survey's ground points held out, the mesh's check


def real_sources(work: Path) -> dict:
    """The real samples of ../shared/data/real as the chain's inputs, each with the options it
    needs: the Québec LiDAR (0.1 ground points/m², lakes), the Autzen LiDAR (Oregon, 0.4 ground
    points/m², a river bank; its feet scaled to metres: EPSG:2994 and EPSG:2993 are the same
    Lambert projection in feet and in metres) and the Merewether DEM (1 m, urban; its held-out
    cells are taken out of the DEM and filled from their neighbours)."""
    import laspy

    from floodmesh.core.points import PointCloud

    sources = {"Québec LiDAR (Topography.laz)": (REAL / "Topography.laz", {}),
               "Merewether DEM (1 m)": (REAL / "merewether_topography1.asc",
                                        {"crs": "EPSG:32756"})}
    las = laspy.read(REAL / "autzen_trim.laz")
    ground = np.asarray(las.classification) == 2
    xyz = 0.3048 * np.column_stack([las.x, las.y, las.z])[ground]
    io.write_points_las(work / "autzen_m.laz", PointCloud(xyz, CRS.from_epsg(2993)))
    sources["Autzen LiDAR (autzen_trim.laz, in metres)"] = (work / "autzen_m.laz", {})
    return sources


def run_real(name, source, extra, chains, work: Path):
    """A real sample: the chain's nodes and held-out RMSE against uniform 25° meshes (node z
    from the run's DEM) on the same held-out points, nodes per FloodMesh node at that RMSE."""
    rows, dem, check = [], None, None
    for chain in chains:
        out = work / chain
        report = run_pipeline(source, out, RunOptions(holdout=REAL_HOLDOUT, **extra,
                                                      **CHAINS[chain]))
        rows.append((chain, report["nodes"], report["rmse_m"]))
        dem = io.read_raster(out / "dem.tif")
        check = io.read_points_vector(out / "residuals.gpkg")
    curve = []
    for area in UNIFORM_AREAS:
        mesh = build_mesh(dem, [], min_angle=25, max_area=area)
        z = tin_elevation(mesh, check[:, 0], check[:, 1])
        curve.append((len(mesh.nodes), float(np.sqrt(np.nanmean((z - check[:, 2]) ** 2)))))
    print(f"\n## {name} (held-out RMSE on {len(check):,} points)")
    print(f"{'chain':<14}{'nodes':>8}{'held-out RMSE cm':>18}{'uniform/ours':>14}")
    results = []
    for chain, n, rmse in rows:
        ratio = nodes_at(rmse, curve, extrapolate=False) / n
        print(f"{chain:<14}{n:>8,}{100 * rmse:>18.2f}" + (f"{ratio:>13.1f}x" if np.isfinite(ratio)
                                                          else f"{'below uniform':>14}"))
        results.append((chain, ratio))
    print("uniform 25° (DEM z): " + ", ".join(f"{n:,} nodes {100 * r:.2f} cm"
                                             for n, r in curve[::2]))
    return results


def main():
    parser = argparse.ArgumentParser(description=__doc__,
                                     formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--quick", action="store_true",
                        help="only the reference case (demo geometry, 9 points/m², 5 cm)")
    parser.add_argument("--terrains", default="all",
                        help="terrains of benchmarks/corpus.py by the start of their names, "
                             "comma-separated (default all: " + "; ".join(TERRAINS) + ")")
    parser.add_argument("--noise", default="0.05,0.15", help="noise (m), comma-separated")
    parser.add_argument("--density", default="9,2",
                        help="ground points per m², comma-separated (the corpus: 1 to 16)")
    parser.add_argument("--real", action="store_true",
                        help="also the real samples of ../shared/data/real, scored on "
                             "held-out points (no true lines)")
    parser.add_argument("--chains", default="landed,default,no-join,no-spacing",
                        help=f"option sets to run, of {', '.join(CHAINS)}")
    args = parser.parse_args()
    chains = args.chains.split(",")
    chosen = [t for t in TERRAINS if args.terrains == "all"
              or any(t.startswith(w.strip()) for w in args.terrains.split(","))]
    cases = [(t, float(n), float(d)) for t in chosen for n in args.noise.split(",")
             for d in args.density.split(",")]
    if args.quick:
        cases = cases[:1]
    summary = []
    with tempfile.TemporaryDirectory() as tmp:
        for terrain, noise, density in cases:
            floodplain, seed = TERRAINS[terrain]
            for chain, ratio, score in run_case(terrain, floodplain, seed, noise, density,
                                                chains, Path(tmp)):
                summary.append((terrain, noise, density, chain, ratio, score))
    if args.real:
        with tempfile.TemporaryDirectory() as tmp:
            for name, (source, extra) in real_sources(Path(tmp)).items():
                for chain, ratio in run_real(name, source, extra, chains, Path(tmp)):
                    summary.append((name, np.nan, np.nan, chain, ratio, None))
    print("\n## Summary: nodes a uniform 25° mesh needs for the same true RMSE, per FloodMesh "
          "node (bars: 15x reference case, goal 30x and 10x at 15 cm)")
    for terrain, noise, density, chain, ratio, score in summary:
        if score is None:  # a real sample: held-out RMSE, no true lines
            print(f"{terrain:<28}  held-out     {chain:<10}{ratio:>6.1f}x")
            continue
        print(f"{terrain:<28}{density:>4g}/m² {100 * noise:>3g} cm  {chain:<10}{ratio:>6.1f}x  "
              f"pieces {score['mean_pieces']:.2f}  recall {score['recall']:.3f}  "
              f"precision {score['precision']:.3f}  breaks {score['breaks']}  "
              f"segments dropped {score['dropped']}  T-junctions snapped {score['t_junctions']}  "
              f"CFL {score['cfl']:.1f}x uniform (smallest inradius {score['min_inradius']:.2f} m)"
              + (f"  crest {100 * max(score['crest_m'].values(), key=abs):+.1f} cm"
                 if score["crest_m"] else ""))


if __name__ == "__main__":
    main()
