"""Virtual bulk tests in Yade: angle of repose and tilt table (the paper's §3.2, in silico), and a drained
triaxial test in a periodic cell (:mod:`grainforge.simulate.triaxial`).

The paper printed 8,000 CRI grains of two shapes and measured, on a tilt
table, ultimate friction angles of about 38° for "rough spheres" and 43–48° for
"rough and angular" grains.  :func:`run_test` runs the same kind of
comparison in the DEM engine Yade before anything is printed:

1. the population's grains (mesh files, a run folder, a manifest, or grains
   generated from a recipe) become clumps through :mod:`grainforge.dem`, each
   carrying the mesh's exact mass, centre and inertia;
2. a Yade deck is written with a scene from :mod:`grainforge.simulate.yade_scenes`
   (a lifted cylinder on a rough base for the angle of repose; a periodic layer
   on a rough plate tilted until it slides for the tilt table) and run headless
   (``yade -n -x run.py``) once per seed;
3. the angle is measured from the final grain positions by
   :mod:`grainforge.simulate.angles`, and reported with its spread over seeds.

Every shape gets the same contact model (linear spring, Coulomb friction:
Yade's Cundall–Strack law), the same material and the same time-step rule.
Nothing is tuned to the paper's numbers; the contact friction is an input.

The whole run of ``grainforge simulate TEST`` (checks, journal, estimate, templates, staged outputs) is
:func:`run_virtual_test`; a friction calibration's, :func:`calibrate_friction`; a calibration of μ and the
rolling resistance μ_r together against several tests, :func:`calibrate_material`.
"""

from .calibration import CalibrationFailed, CalibrationResult, calibrate_friction
from .engine import EngineFailed, measure_result, run_test, run_yade, summarise, write_test_deck, yade_executable
from .material import MaterialCalibration, calibrate_material
from .pipeline import VirtualTestResult, run_virtual_test, settings_for
from .run_folders import FAILED_PREFIX, commit_stage, discard_stage, keep_failed, open_stage, staged
from .settings import QUICK, QUICK_REPOSE, QUICK_TRIAXIAL, TESTS, Settings, TriaxialSettings, check_size, scene_settings
from .specimen import build_population, check_inputs

__all__ = ["TESTS", "Settings", "TriaxialSettings", "QUICK", "QUICK_REPOSE", "QUICK_TRIAXIAL", "yade_executable", "scene_settings", "check_inputs", "build_population",
           "write_test_deck", "run_yade", "measure_result", "run_test", "summarise", "check_size", "open_stage", "staged",
           "commit_stage", "discard_stage", "EngineFailed", "keep_failed", "FAILED_PREFIX", "settings_for", "run_virtual_test",
           "VirtualTestResult", "calibrate_friction", "CalibrationResult", "CalibrationFailed", "calibrate_material",
           "MaterialCalibration"]
