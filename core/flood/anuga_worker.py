"""The ANUGA side of ``core.flood.model``: a script run by the flood environment's Python
(numpy >= 2 and ``anuga``), never imported by FloodMesh itself (it needs nothing of FloodMesh).

``python anuga_worker.py JOB_DIR`` reads ``JOB_DIR/job.npz`` (nodes, triangles, vertex
elevations, per-triangle Manning's n, tagged boundary edges, inflows, observation triangles)
and ``JOB_DIR/job.json`` (duration, output interval, boundary kinds), runs ANUGA (flow algorithm
DE0), and writes ``JOB_DIR/result.npz``: per triangle the maximum depth, water level and speed
and the arrival time, and per output time the water volume, the inflow applied, the boundary
flux integral and the stage and depth at each observation triangle (and its bed once), and per
triangle how often it set the time step (at the checks below: the triangle of least inradius
over its fastest wave in the step before, and the steps since the last check). On stdout it
prints ``progress T`` after each output time T (s) for the parent's progress bar.

At each output time, and at least every ``CHECK_INTERVAL_S`` of flood time, it checks that
the solution is still a flood: where the water turns non-finite, or water deeper than the wet
depth runs faster than ``unstable_speed_m_s``, it writes ``JOB_DIR/unstable.json`` (time,
triangle, depth, speed, time step) instead of a result and exits with ``UNSTABLE_EXIT``. A
blow-up otherwise goes on to the end (depths of 100 m and more, a balanced mass budget) or
crawls for hours at time steps of 0.0001 s.
"""
import json
import math
import sys
import time

import numpy as np

UNSTABLE_EXIT = 3
CHECK_INTERVAL_S = 10.0  # flood time between checks at most: an output interval is split


def _series(times, values):
    """f(t) by linear interpolation, held at the first and last values outside the series."""
    times, values = np.asarray(times, float), np.asarray(values, float)
    return lambda t: float(np.interp(t, times, values))


def _outflow(anuga, domain):
    """An open boundary that lets water out and never draws it in: ANUGA's transmissive
    boundary (outside = inside), less the normal momentum of an edge whose water moves back
    into the domain. Transmissive as it is feeds such an edge from an endless reservoir: on a
    falling limb an eddy at the outflow edge drew water in until it ran at 20 m/s and piled up
    to 450 m (benchmarks/RESULTS.md, "An outflow edge that blew up"). Where the water leaves,
    the two are the same."""

    class Outflow(anuga.Transmissive_boundary):
        def evaluate_segment(self, domain, segment_edges):
            super().evaluate_segment(domain, segment_edges)
            if segment_edges is None or domain is None:
                return
            cells = domain.boundary_cells[segment_edges]
            edges = domain.boundary_edges[segment_edges]
            nx, ny = domain.normals[cells, 2 * edges], domain.normals[cells, 2 * edges + 1]
            xmom = domain.quantities["xmomentum"].boundary_values
            ymom = domain.quantities["ymomentum"].boundary_values
            inward = np.minimum(xmom[segment_edges] * nx + ymom[segment_edges] * ny, 0.0)
            xmom[segment_edges] -= inward * nx
            ymom[segment_edges] -= inward * ny

    return Outflow(domain)


def _boundary_objects(anuga, domain, kinds: dict):
    objects = {}
    for tag, spec in kinds.items():
        kind = spec["kind"]
        if kind == "wall":
            objects[tag] = anuga.Reflective_boundary(domain)
        elif kind == "outflow":
            objects[tag] = _outflow(anuga, domain)
        elif kind == "level":
            if spec.get("levels"):
                times, levels = zip(*spec["levels"])
                stage = _series(times, levels)
            else:
                stage = (lambda t, level=float(spec["level_m"]): level)
            # water at rest outside at that level: the Riemann flux lets water in while the
            # inside is lower and out once it is higher (transmitting the normal momentum
            # instead kept a filling basin's inflow going: 0.7 m above the level on the demo)
            objects[tag] = anuga.Time_boundary(
                domain, function=(lambda t, stage=stage: [stage(t), 0.0, 0.0]))
        else:
            raise ValueError(f"unknown boundary kind {kind}")
    return objects


def _unstable(stage, depth, speed, wet: float, limit: float):
    """The triangle where the solution is no longer a flood (its state not finite, or water
    deeper than ``wet`` m faster than ``limit`` m/s), the fastest such; None when there is none."""
    broken = np.flatnonzero(~(np.isfinite(stage) & np.isfinite(speed)))
    if len(broken):
        return int(broken[0])
    fast = np.where(depth > wet, speed, 0.0)
    k = int(np.argmax(fast))
    return k if fast[k] > limit else None


def run(job_dir: str) -> None:
    # lazy: optional, in the flood environment only
    import anuga

    with open(f"{job_dir}/job.json") as fh:
        job = json.load(fh)
    data = np.load(f"{job_dir}/job.npz")
    nodes, triangles = data["nodes"], data["triangles"]
    tags = job["boundary_tags"]
    boundary = {(int(t), int(e)): tags[int(k)]
                for t, e, k in data["boundary_edges"]}
    domain = anuga.Domain(nodes[:, :2], triangles, boundary=boundary, verbose=False)
    domain.set_flow_algorithm(job.get("flow_algorithm", "DE0"))
    domain.set_name("flood")
    domain.set_store(False)
    # a dry domain allows any time step; an inflow onto it then arrives in one leap
    domain.set_evolve_max_timestep(float(job.get("max_time_step_s", 1.0)))
    domain.set_quantity("elevation", data["vertex_z"], location="vertices")
    domain.set_quantity("friction", data["manning"], location="centroids")
    initial = job.get("initial_stage_m")
    if initial is None:
        domain.set_quantity("stage", expression="elevation")
    else:
        # a level lake at the centroids, where DE0 keeps its state (clipping the vertices
        # would tilt the water in triangles the shore crosses)
        bed = domain.quantities["elevation"].centroid_values
        domain.set_quantity("stage", np.maximum(bed, float(initial)), location="centroids")
    domain.set_boundary(_boundary_objects(anuga, domain, job["boundary_kinds"]))

    inlets = []
    for k, inflow in enumerate(job["inflows"]):
        region = data[f"inflow_{k}"].tolist()
        if "times_s" in inflow:
            q = _series(inflow["times_s"], inflow["rates_m3s"])
        else:
            q = float(inflow["discharge_m3s"])
        inlets.append(anuga.Inlet_operator(domain, region, Q=q, verbose=False))

    area = domain.areas
    obs = data["observation_triangles"].astype(int)
    wet = float(job["wet_depth_m"])
    limit = float(job["unstable_speed_m_s"])
    n_tri = len(triangles)
    max_depth = np.zeros(n_tri)
    max_stage = np.full(n_tri, -np.inf)
    max_speed = np.zeros(n_tri)
    arrival = np.full(n_tri, np.nan)
    times, volume, applied, flux, obs_stage, obs_depth, steps = [], [], [], [], [], [], []
    done = [0]  # time steps so far: ANUGA counts them per output interval
    # the triangle whose inradius over its fastest wave (ANUGA's own: its flux time step is
    # the least of radii / max_speed) set the last step before each check, and the steps of
    # the interval that check closes
    step_setter_checks = np.zeros(n_tri, dtype=np.int64)
    step_setter_steps = np.zeros(n_tri, dtype=np.int64)

    def take_step_setter(steps_done: int) -> None:
        wave = domain.max_speed
        with np.errstate(divide="ignore"):
            cell_step = np.where(wave > 0, domain.radii / np.where(wave > 0, wave, 1.0), np.inf)
        k = int(np.argmin(cell_step))
        if np.isfinite(cell_step[k]):
            step_setter_checks[k] += 1
            step_setter_steps[k] += steps_done

    def sample(t, record=True):
        """The state at ``t`` checked (``_unstable``'s finding, or None) and, with ``record``,
        taken into the maxima and series."""
        stage = domain.quantities["stage"].centroid_values
        bed = domain.quantities["elevation"].centroid_values
        depth = np.maximum(stage - bed, 0.0)
        xmom = domain.quantities["xmomentum"].centroid_values
        ymom = domain.quantities["ymomentum"].centroid_values
        with np.errstate(divide="ignore", invalid="ignore"):
            # speed in films thinner than 1 cm is noise at wet/dry fronts, not flow
            speed = np.where(depth > 0.01, np.hypot(xmom, ymom) / depth, 0.0)
        k = _unstable(stage, depth, speed, wet, limit)
        if k is not None:
            return {"time_s": t, "triangle": k, "depth_m": float(stage[k] - bed[k]),
                    "speed_ms": float(speed[k]), "time_step_s": float(domain.timestep)}
        if not record:
            return None
        np.maximum(max_depth, depth, out=max_depth)
        np.maximum(max_stage, np.where(depth > 0, stage, bed), out=max_stage)
        np.maximum(max_speed, speed, out=max_speed)
        arrival[np.isnan(arrival) & (depth > wet)] = t
        times.append(t)
        volume.append(float((depth * area).sum()))
        applied.append(float(sum(i.get_total_applied_volume() for i in inlets)))
        flux.append(float(domain.get_boundary_flux_integral()))
        obs_stage.append(np.where(obs >= 0, stage[np.maximum(obs, 0)], np.nan))
        obs_depth.append(np.where(obs >= 0, depth[np.maximum(obs, 0)], np.nan))
        steps.append(done[0])
        return None

    interval, duration = float(job["output_interval_s"]), float(job["duration_s"])
    checks = max(1, math.ceil(interval / CHECK_INTERVAL_S - 1e-9))  # per output interval
    start = time.process_time()
    sample(0.0)
    for n, t in enumerate(domain.evolve(yieldstep=interval / checks, finaltime=duration)):
        t = float(t)
        done[0] += int(domain.number_of_steps)
        if t > 0:
            take_step_setter(int(domain.number_of_steps))
        unstable = sample(t, n % checks == 0 or t >= duration - 1e-9) if t > 0 else None
        if unstable is not None:
            with open(f"{job_dir}/unstable.json", "w") as fh:
                json.dump(unstable, fh)
            sys.exit(UNSTABLE_EXIT)
        print(f"progress {t:.3f}", flush=True)
    cpu = time.process_time() - start
    np.savez(f"{job_dir}/result.npz", max_depth=max_depth, max_stage=max_stage,
             max_speed=max_speed, arrival_s=arrival, times_s=np.array(times),
             volume_m3=np.array(volume), inflow_applied_m3=np.array(applied),
             boundary_flux_m3=np.array(flux),
             observation_stage_m=np.array(obs_stage).reshape(len(times), len(obs)),
             observation_depth_m=np.array(obs_depth).reshape(len(times), len(obs)),
             observation_bed_m=domain.quantities["elevation"].centroid_values[obs],
             steps=np.array(steps), cpu_s=np.array(cpu),
             step_setter_checks=step_setter_checks, step_setter_steps=step_setter_steps,
             anuga_version=np.array(anuga.__version__))


if __name__ == "__main__":
    run(sys.argv[1])
