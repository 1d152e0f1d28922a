"""licvdb.bake_fluid: LIC from a Blender smoke simulation's OpenVDB cache; and what every bake
operator shares (recipes from the scene's settings, BakeJob, BakeRunner).

For the selected fluid domain (gas, cache format OpenVDB) this writes a recipe from the scene's
bake settings, runs ``licvdb bake`` on the cache's ``velocity`` grid in a subprocess (one
coherent sequence for a frame range), shows progress, can be cancelled with Esc, and imports the
result placed on the domain. ops_bake_file.py bakes a flow file the same way.
"""

import json
import os
import shutil
import signal
import subprocess
import tempfile
import time
import traceback

import bpy
from mathutils import Matrix, Vector

from . import manifest as mf
from . import engine, ops_import, prefs, progress, props, roi, seeds


class BakeError(Exception):
    """A bake that cannot start or failed; the message says what to do."""


# --- the fluid domain ---------------------------------------------------------------------------

def fluid_domain(obj):
    """The domain settings of ``obj``'s fluid modifier if it is a gas domain, else None."""
    if obj is None:
        return None
    for m in obj.modifiers:
        if m.type == "FLUID" and m.fluid_type == "DOMAIN" and m.domain_settings.domain_type == "GAS":
            return m.domain_settings
    return None


def cache_data_file(ds, frame: int) -> str:
    """The OpenVDB data cache file mantaflow writes for ``frame``."""
    return os.path.join(bpy.path.abspath(ds.cache_directory), "data", f"fluid_data_{frame:04d}.vdb")


def cache_data_pattern(ds) -> str:
    """The cache's data files as a licvdb frame pattern (fluid_data_####.vdb)."""
    return os.path.join(bpy.path.abspath(ds.cache_directory), "data", "fluid_data_####.vdb")


def domain_local_cell(obj, ds) -> Vector:
    """Size of one simulation cell in the domain object's local units."""
    corners = [Vector(c) for c in obj.bound_box]
    lo = Vector([min(c[a] for c in corners) for a in range(3)])
    hi = Vector([max(c[a] for c in corners) for a in range(3)])
    size = hi - lo
    res = tuple(ds.domain_resolution)
    if all(r > 0 for r in res):
        return Vector([size[a] / res[a] for a in range(3)])
    cell = max(size) / ds.resolution_max
    return Vector((cell, cell, cell))


def domain_placement(obj, ds, cache_voxel: float) -> Matrix:
    """World matrix that puts grids written in the cache's coordinates onto the domain.

    Mantaflow writes the data cache with a plain linear transform: voxel (i, j, k) at
    (i, j, k) × cache_voxel, i.e. relative to the domain's lower corner and without the half cell
    that separates a cell's centre from its corner. Cell (i, j, k) of the simulation covers
    [lower + i·cell, lower + (i+1)·cell] in the domain's local space, so its centre is
    lower + (i + ½)·cell. (Non-adaptive domains; an adaptive domain moves its grid per frame.)
    """
    corners = [Vector(c) for c in obj.bound_box]
    lower = Vector([min(c[a] for c in corners) for a in range(3)])
    cell = domain_local_cell(obj, ds)
    scale = Matrix.Diagonal(Vector([cell[a] / cache_voxel for a in range(3)] + [1.0]))
    return obj.matrix_world @ Matrix.Translation(lower + 0.5 * cell) @ scale


def cache_voxel_size(path: str) -> float:
    """The voxel size of the velocity grid in the cache file ``path`` (read by Blender). Raises BakeError."""
    probe = bpy.data.volumes.new("licvdb cache probe")
    try:
        probe.filepath = path
        if not probe.grids.load():
            raise BakeError(f"Blender cannot read {path}: {probe.grids.error_message or 'unknown error'}")
        grid = probe.grids.get("velocity") or (probe.grids[0] if len(probe.grids) else None)
        if grid is None:
            raise BakeError(f"{path} has no grids")
        return grid.matrix_object.to_scale()[0]
    finally:
        bpy.data.volumes.remove(probe)


# --- recipes and the subprocess -------------------------------------------------------------------

def make_recipe(settings, field_path: str, out_path: str, loop_frames: int = 1, grid: str = "velocity") -> dict:
    """The recipe JSON for one bake of ``field_path`` from the scene's bake settings; ``grid`` is
    the field's vector grid ("" = licvdb's default choice)."""
    recipe = {
        "field": {"path": field_path, "grid": grid},
        "output": {"path": out_path, "upsample": settings.upsample},
        "input": ({"type": "noise", "seed": settings.seed} if settings.input_type == "noise" else
                  {"type": "spots", "seed": settings.seed, "spacing": settings.spot_spacing,
                   "radii": [settings.spot_radius], "halo_scale": settings.halo_scale}),
        "lic": {"kernel": settings.kernel, "length": settings.length},
        "animation": {"frames": loop_frames},
        "threads": settings.threads,
    }
    if not grid:
        del recipe["field"]["grid"]
    if settings.kernel == "exp":
        recipe["lic"]["decay"] = settings.decay
    if settings.color_scalar != "NONE":
        recipe["color"] = {"scalar": settings.color_scalar, "colormap": settings.colormap}
    if settings.roi_scalar != "NONE":
        recipe["roi"] = roi_recipe(settings)
    return recipe


def roi_recipe(settings) -> dict:
    """The recipe's ``roi`` from the bake settings; a range relative to the top speed is written
    as ``{"fraction_of_top_speed": [lo, hi]}`` for BakeJob to resolve (roi.py)."""
    lo, hi = sorted(settings.roi_range)
    relative = settings.roi_relative and settings.roi_scalar == "speed"
    return {"scalar": settings.roi_scalar, "range": {roi.RELATIVE: [lo, hi]} if relative else [lo, hi],
            "mode": settings.roi_mode}


def output_dir(settings, default: str) -> str:
    """The bake settings' output folder, else ``default``; created. Raises BakeError."""
    out_dir = bpy.path.abspath(settings.output_dir) if settings.output_dir else default
    try:
        os.makedirs(out_dir, exist_ok=True)
    except OSError as e:
        raise BakeError(f"cannot create the output folder {out_dir}: {e.strerror}; set another one under "
                        "Output in the licvdb panel") from None
    return out_dir


def new_bake_base(out_dir: str, stem: str) -> str:
    """``out_dir/STEM_lic_TIME``: a new name for every bake (Blender does not notice a .vdb
    overwritten in place)."""
    run = time.strftime("%Y%m%d_%H%M%S") + f"_{int(time.time() * 1000) % 1000:03d}"
    return os.path.join(out_dir, f"{bpy.path.clean_name(stem)}_lic_{run}")


def settings_dict(settings) -> dict:
    """The scene's bake settings (``scene.licvdb_bake``) as a plain dict, for a result to remember."""
    out = {}
    for p in settings.bl_rna.properties:
        if p.identifier in ("rna_type", "name"):
            continue
        value = getattr(settings, p.identifier)
        if isinstance(value, bpy.types.ID):
            value = value.name  # (the seed object: its name)
        elif getattr(p, "is_array", False):
            value = list(value)  # (the region's range)
        out[p.identifier] = value
    return out


def add_seeds(context, settings, recipe: dict, base: str, to_field=None, unsteady: str = "") -> str:
    """seeds.apply (the seed object's points as the recipe's spots), its errors as BakeError."""
    try:
        return seeds.apply(context, settings, recipe, base, to_field, unsteady)
    except seeds.SeedError as e:
        raise BakeError(str(e)) from None


def unsteady_recipe(context, settings, pattern: str, frames: list, base: str, fps: float, unsteady: str,
                    grid: str = "velocity"):
    """(recipe, output files) of ONE unsteady sequence over the field files ``pattern`` (``####`` =
    the frame number) numbered ``frames`` (consecutive): licvdb writes ``BASE_FFFF.vdb`` numbered as
    the field's frames and one manifest; ``fps`` frames per second turn velocities (world units per
    second) into motion between frames. ``unsteady`` names the sequence in errors (a seed object
    is refused). Raises BakeError."""
    recipe = make_recipe(settings, pattern, f"{base}.vdb", 1, grid=grid)
    recipe["field"]["frames"] = [frames[0], frames[-1]]
    recipe["field"]["fps"] = fps
    add_seeds(context, settings, recipe, base, unsteady=unsteady)
    return recipe, [f"{base}_{f:04d}.vdb" for f in frames]


def scene_fps(scene) -> float:
    return scene.render.fps / scene.render.fps_base


def record_source(obj, kind: str, used: dict, source_object=None, source_path: str = "", grid: str = ""):
    """Remember on a bake result what it was baked from (``obj.licvdb.source_*``) and the settings
    it used (``used``: settings_dict when the bake was planned), so licvdb.rebake can bake it
    again. ``kind``: FLUID, FILE or VOLUME."""
    s = obj.licvdb
    s.source_kind = kind
    s.source_object = source_object
    s.source_path = source_path
    s.source_grid = grid
    s.bake_settings = json.dumps(used, sort_keys=True)


class BakeJob:
    """Runs ``licvdb bake --recipe …`` for a list of tasks, one subprocess at a time.

    Non-blocking: call ``poll()`` from a timer (or ``run()`` to block). ``cancel()`` interrupts the
    running bake (SIGINT: licvdb stops and writes nothing), and removes what earlier tasks of this
    job wrote, so a cancelled job leaves no files.
    """

    def __init__(self, executable: str, tasks):
        self.executable = executable
        self.tasks = list(tasks)  # [(label, recipe dict)]
        self.workdir = tempfile.mkdtemp(prefix="licvdb_job_")  # recipes and stderr; removed at the end
        self.index = -1
        self.proc = None
        self.stderr_file = None
        self.error = None  # message when a task failed
        self.cancelled = False
        self.done_outputs = []  # (label, output path) of finished tasks
        self.started = time.monotonic()
        self.task_started = self.started
        self.stage, self.stage_fraction = "", 0.0  # of the running task, from licvdb's progress lines
        self._stderr_pos = 0
        self.progress_seen = []  # every (stage, fraction) read, for tests and the console

    @property
    def finished(self) -> bool:
        done = self.error is not None or self.cancelled or self.index >= len(self.tasks)
        if done and os.path.isdir(self.workdir) and (self.proc is None or self.proc.poll() is not None):
            if self.stderr_file is not None and not self.stderr_file.closed:
                self.stderr_file.close()
            shutil.rmtree(self.workdir, ignore_errors=True)
        return done

    @property
    def fraction(self) -> float:
        """Overall progress in [0, 1]: finished tasks plus the running task's fraction (one rising
        fraction from licvdb's per-stage ones: progress.task_fraction)."""
        self._read_progress()
        running = progress.task_fraction(self.stage, self.stage_fraction) if self.stage else 0.0
        return min(1.0, (len(self.done_outputs) + running) / max(1, len(self.tasks)))

    def _read_progress(self):
        """Parse the newest ``progress FRACTION STAGE`` line licvdb wrote (``--progress lines``)."""
        f = self.stderr_file
        if f is None or f.closed:
            return
        f.seek(self._stderr_pos)
        chunk = f.read()
        if not chunk:
            return
        complete, _, rest = chunk.rpartition("\n")
        self._stderr_pos += len(complete) + 1 if complete else 0
        for line in reversed(complete.splitlines()):
            parts = line.split(" ", 2)
            if len(parts) == 3 and parts[0] == "progress":
                try:
                    self.stage_fraction = float(parts[1])
                except ValueError:
                    continue
                self.stage = parts[2]
                self.progress_seen.append((self.stage, self.stage_fraction))
                break

    def status(self) -> str:
        n = len(self.tasks)
        label = self.tasks[self.index][0] if 0 <= self.index < n else ""
        stage = f", {self.stage} {100 * self.stage_fraction:.0f}%" if self.stage and self.stage_fraction >= 0 else ""
        elapsed = time.monotonic() - self.started
        eta = progress.eta_text(elapsed, self.fraction)
        return (f"licvdb: baking {label} ({min(self.index + 1, n)}/{n}{stage}), "
                f"{elapsed:.0f} s{', ' + eta if eta else ''}, Esc to cancel")

    def _start_next(self):
        self.index += 1
        if self.index >= len(self.tasks):
            return
        label, recipe = self.tasks[self.index]
        try:
            roi.resolve(self.executable, recipe)  # a region relative to the top speed → the field's speeds
        except roi.RoiError as e:
            self.error = f"licvdb bake of {label}: region of interest: {e}"
            self._remove_outputs()
            return
        recipe_path = os.path.join(self.workdir, f"recipe_{self.index:04d}.json")
        with open(recipe_path, "w", encoding="utf-8") as f:
            json.dump(recipe, f, indent=2)
        # licvdb writes stderr to a file we read with our own file offset (a shared descriptor
        # would make our reads move the child's write position).
        stderr_path = os.path.join(self.workdir, f"stderr_{self.index:04d}.txt")
        self._stderr_pos = 0
        self.stage, self.stage_fraction = "", 0.0
        self.task_started = time.monotonic()
        try:
            with open(stderr_path, "wb") as child_err:
                self.proc = subprocess.Popen([self.executable, "bake", "--recipe", recipe_path, "--json",
                                              "--progress", "lines"],
                                             stdout=subprocess.PIPE, stderr=child_err, text=True,
                                             env=engine.engine_env())
        except OSError as e:
            self.error = f"cannot run {self.executable}: {e}; check the path in the add-on preferences"
            return
        self.stderr_file = open(stderr_path, encoding="utf-8", errors="replace")

    def start(self):
        self._start_next()
        return self

    def poll(self) -> bool:
        """Advance; True once the job is finished (done, failed or cancelled)."""
        if self.finished:
            return True
        if self.proc.poll() is None:
            return False
        out = self.proc.stdout.read()
        self._read_progress()
        self.stderr_file.seek(0)
        err = "\n".join(l for l in self.stderr_file.read().splitlines() if not l.startswith("progress "))
        self.stderr_file.close()
        label, recipe = self.tasks[self.index]
        if self.proc.returncode != 0:
            lines = err.splitlines()
            errors = [l for l in lines if "error" in l.lower()]
            last = " ".join(errors or lines[-1:]) or f"exit code {self.proc.returncode}"
            hint = engine.missing_module_hint(last) or (
                "check the bake settings" if self.proc.returncode == 2 else "see the system console for details")
            self.error = f"licvdb bake failed for {label}: {last} ({hint})"
            self._remove_outputs()
            return True
        try:
            summary = json.loads(out)
        except ValueError:
            summary = {}
        self.done_outputs.append((label, recipe["output"]["path"], summary))
        self._start_next()
        return self.finished

    def run(self, timeout: float | None = None):
        """Block until finished."""
        self.start()
        t0 = time.monotonic()
        while not self.poll():
            if timeout is not None and time.monotonic() - t0 > timeout:
                self.cancel()
                self.error = f"licvdb bake took longer than {timeout} s"
                break
            time.sleep(0.05)
        return self

    def cancel(self, grace: float = 5.0):
        """Stop the running bake and remove this job's outputs."""
        self.cancelled = True
        if self.proc is not None and self.proc.poll() is None:
            self.proc.send_signal(signal.SIGINT)  # licvdb stops at the next check, writes nothing
            try:
                self.proc.wait(grace)
            except subprocess.TimeoutExpired:
                self.proc.kill()
                self.proc.wait()
        if self.stderr_file is not None and not self.stderr_file.closed:
            self.stderr_file.close()
        self._remove_outputs()

    def _remove_outputs(self):
        for _, recipe in self.tasks:  # the seeds the add-on wrote beside the output (seeds.apply)
            written = recipe.get("input", {}).get("seeds", "")
            if written.endswith(".seeds.txt") and os.path.isfile(written):
                os.remove(written)
        for _, out, summary in self.done_outputs:
            written = list(summary.get("files", [])) + [summary.get("manifest", "")]
            if not summary:  # no summary to go by: the still and its manifest
                written = [out, mf.manifest_path(out)]
            for p in written:
                if p and os.path.isfile(p):
                    os.remove(p)
        self.done_outputs = []


def plan_bake(context, obj):
    """(job, finish) for baking the domain ``obj`` with the scene's settings. ``finish(context)``
    imports the result and returns the new object. Raises BakeError with what to do."""
    ds = fluid_domain(obj)
    if ds is None:
        raise BakeError("select a fluid domain of type Gas (smoke) to bake LIC from")
    if ds.cache_data_format != "OPENVDB":
        raise BakeError(f"the fluid cache format is {ds.cache_data_format}; set Physics > Fluid > Cache > "
                        "Format Volumes to OpenVDB and bake the simulation again")
    exe = prefs.find_executable(context)
    if exe is None:
        raise BakeError(prefs.missing_executable_message(context))
    settings = context.scene.licvdb_bake
    if settings.use_frame_range:
        first, last = ((ds.cache_frame_start, ds.cache_frame_end) if settings.range_from_cache
                       else (settings.frame_start, settings.frame_end))
        if last < first:
            raise BakeError(f"frame range {first}-{last} is empty")
        if settings.loop_frames > 1:
            raise BakeError("loop frames > 1 bakes one simulation frame as a loop: turn off Frame range "
                            "or set Loop frames to 1")
        frames = list(range(first, last + 1))
    else:
        frames = [context.scene.frame_current]
    missing = [f for f in frames if not os.path.isfile(cache_data_file(ds, f))]
    if missing:
        raise BakeError(f"no OpenVDB cache for frame {missing[0]} ({cache_data_file(ds, missing[0])}): bake "
                        "the simulation first (Physics > Fluid > Bake Data)")
    out_dir = output_dir(settings, os.path.join(bpy.path.abspath(ds.cache_directory), "licvdb"))
    base = new_bake_base(out_dir, obj.name)
    if len(frames) > 1:
        # One coherent unsteady sequence: the texture is carried by the smoke from frame to frame
        # (licvdb writes BASE_FFFF.vdb numbered as the cache, and one manifest).
        # Mantaflow's velocities are converted to world units per second by licvdb; the scene's
        # frame rate (slowed by the simulation's time scale) gives the time between frames.
        recipe, outs = unsteady_recipe(context, settings, cache_data_pattern(ds), frames, base,
                                       scene_fps(context.scene) / max(ds.time_scale, 1e-6),
                                       f"the frame range {frames[0]}-{frames[-1]}")
        tasks = [(f"frames {frames[0]}-{frames[-1]}", recipe)]
    else:
        out = f"{base}_f{frames[0]:04d}.vdb"
        recipe = make_recipe(settings, cache_data_file(ds, frames[0]), out, settings.loop_frames)
        if settings.seed_object is not None:  # world → the cache's coordinates (domain_placement inverted)
            to_field = domain_placement(obj, ds, cache_voxel_size(cache_data_file(ds, frames[0]))).inverted()
            add_seeds(context, settings, recipe, base, to_field)
        tasks = [(f"frame {frames[0]}", recipe)]
        outs = [out]
    job = BakeJob(exe, tasks)
    domain_name = obj.name
    loop_frames = settings.loop_frames
    used = settings_dict(settings)

    def finish(ctx):
        dom = ctx.scene.objects.get(domain_name)
        if len(outs) > 1:
            new = ops_import.import_bake(ctx, outs[0], files=outs, frame_start=frames[0], sequence_mode="CLIP",
                                         setup_render=True)
        elif loop_frames > 1:  # licvdb wrote OUT_0001.vdb … and one manifest OUT.licvdb.json
            new = ops_import.import_bake(ctx, outs[0][:-len(".vdb")] + "_0001.vdb", setup_render=True)
        else:
            new = ops_import.import_bake(ctx, outs[0], setup_render=True)
        summary = job.done_outputs[0][2] if job.done_outputs else {}
        voxel = new.licvdb.voxel_size * settings.upsample
        if dom is not None and fluid_domain(dom) is not None:
            shift = new.matrix_world.to_translation()  # −½ output voxel or zero, see prefs.half_voxel_shift
            new.matrix_world = domain_placement(dom, fluid_domain(dom), voxel) @ Matrix.Translation(shift)
            # Lines are in the cache's units; the look scales strengths by the voxel's world size.
            new.licvdb.voxel_size = new.licvdb.voxel_size * new.matrix_world.to_scale()[0]
            props.apply_look(new)
        new["licvdb_field"] = summary.get("field", {}).get("path", "")
        record_source(new, "FLUID", used, source_object=dom)
        return new

    return job, finish


class BakeRunner:
    """What the bake operators share (a mix-in before ``bpy.types.Operator``): the subclass's
    ``plan(context)`` returns ``(BakeJob, finish)`` or raises BakeError; ``run_blocking`` runs the
    job to its end (the default execute: scripts, background mode), ``run_modal`` runs it from a
    timer with a progress bar and status text, Esc cancelling (the default invoke). ``finish(context)`` imports the
    result and returns the new object; every failure is reported."""

    timeout: bpy.props.FloatProperty(name="Timeout", default=0.0, min=0.0, options={"SKIP_SAVE"},
                                     description="Blocking runs only: give up after this many seconds (0 = never)")

    _timer = None
    _job = None
    _finish = None
    _look = None  # the scene's look for new bakes when the bake was planned (props.scene_look)
    #: What the report says was done with the result ("licvdb: baked and imported OBJ in 3.1 s").
    done_verb = "baked and imported"
    #: Whether the result gets the bake settings' look (Set look); a re-bake keeps its object's.
    sets_look = True

    def plan(self, context):
        raise NotImplementedError

    def execute(self, context):  # blocking (scripts, background mode)
        return self.run_blocking(context)

    def invoke(self, context, event):  # interactive: modal with a timer, Esc cancels
        return self.run_modal(context)

    def _start(self, context) -> bool:
        try:
            self._job, self._finish = self.plan(context)
        except BakeError as e:
            self.report({"ERROR"}, str(e))
            return False
        self._look = props.scene_look(context.scene.licvdb_bake) if self.sets_look else None
        return True

    def _complete(self, context):
        job = self._job
        if job.error:  # (a timeout also cancels)
            self.report({"ERROR"}, job.error)
            return {"CANCELLED"}
        if job.cancelled:
            self.report({"WARNING"}, "licvdb bake cancelled; nothing was written")
            return {"CANCELLED"}
        try:
            obj = self._finish(context)
            props.apply_scene_look(obj, self._look)
        except Exception as e:  # report (and print the traceback), never swallow
            traceback.print_exc()
            self.report({"ERROR"}, f"baked, but the import failed: {e}")
            return {"CANCELLED"}
        self.report({"INFO"}, f"licvdb: {self.done_verb} {obj.name} in {time.monotonic() - job.started:.1f} s")
        return {"FINISHED"}

    def run_blocking(self, context):
        if not self._start(context):
            return {"CANCELLED"}
        self._job.run(timeout=self.timeout or None)
        return self._complete(context)

    def run_modal(self, context):
        if not self._start(context):
            return {"CANCELLED"}
        self._job.start()
        wm = context.window_manager
        self._timer = wm.event_timer_add(0.2, window=context.window)
        wm.progress_begin(0, 1000)
        wm.modal_handler_add(self)
        self._status(context, self._job.status())
        return {"RUNNING_MODAL"}

    def _status(self, context, text):
        if context.workspace is not None:
            context.workspace.status_text_set(text)
        if context.area is not None:
            context.area.header_text_set(text)

    def _end(self, context):
        wm = context.window_manager
        if self._timer is not None:
            wm.event_timer_remove(self._timer)
            self._timer = None
        wm.progress_end()
        self._status(context, None)

    def modal(self, context, event):
        job = self._job
        if event.type == "ESC":
            job.cancel()
            self._end(context)
            return self._complete(context)
        if event.type == "TIMER":
            if job.poll():
                self._end(context)
                return self._complete(context)
            context.window_manager.progress_update(int(1000 * job.fraction))
            self._status(context, job.status())
        return {"PASS_THROUGH"}

    def cancel(self, context):  # Blender closing the window
        if self._job is not None:
            self._job.cancel()
        self._end(context)


class LICVDB_OT_bake_fluid(BakeRunner, bpy.types.Operator):
    """Bake LIC from the selected smoke domain's OpenVDB cache (current frame, or a frame range) and import it"""

    bl_idname = "licvdb.bake_fluid"
    bl_label = "Bake LIC from fluid"
    bl_options = {"REGISTER", "UNDO"}

    @classmethod
    def poll(cls, context):
        return fluid_domain(context.active_object) is not None

    def plan(self, context):
        return plan_bake(context, context.active_object)


classes = (LICVDB_OT_bake_fluid,)
