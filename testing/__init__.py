"""fbia.testing: conformance checks and pytest fixtures for fbia plugins.

Its fixtures (:mod:`fbia.pytest_plugin`, registered as the pytest plugin ``fbia``) are
available in every test session of an environment where fbia is installed.  A third-party
plugin package proves that its classes behave like fbia's own with a few lines::

    from fbia.testing import check_forward_model, check_measure, check_options


    def test_my_solver_conforms(tmp_path):
        model = MySolverForwardModel(timeout=60.0)
        check_options(MySolverForwardModel)
        check_forward_model(model, {"E": 400.0, "nu": 0.3}, [{"inflow_rate": 100.0}], tmp_path,
                            failing_parameters={"E": 1.0, "nu": 0.3})

    def test_my_measure_conforms():
        check_measure(MyMeasure(), dims=(2,))

Every check raises :class:`ConformanceError` (an ``AssertionError``) with a message that names
the plugin class and the rule it broke; each returns what it computed so that a test can go on
asserting.  The helpers :func:`straight_line_2d`, :func:`mound_2d`, :func:`circle_2d`,
:func:`square_3d` and :func:`sphere_3d` build sample interfaces (lengths in mm) with the
orientation fbia uses: normals point from the solid into the fluid.

:mod:`fbia.testing.oct` makes synthetic OCT-like volumes (a dome on a flat substratum with
speckle, depth attenuation and a noise floor) with their known surface, for the OCT reader
:mod:`fbia.imaging.oct` and its tests and benchmark, and realistic scans of porous biofilms
(``realistic_oct_scan``, ``scan_family``: correlated speckle, pores, shadowing, a window
reflection, a tilted glass or membrane substratum).

Iterators are checked on a problem, e.g. ``check_iterator(lambda: MyIterator(seed=0),
tiny_problem())``.  Fixtures: ``fbia_registry`` (the default registry), ``fbia_installer``
(installs a plugin distribution for one test) and ``fbia_measure_cases``.

A plugin class derives from its kind's base (:class:`fbia.ForwardModelBase`,
:class:`fbia.MeasureBase`, :class:`fbia.IteratorBase`), and the checks refuse one that does
not.  The base's optional members that the conformance tests of fbia (and
:func:`check_registered`) use:

``example_parameters()``
    Forward models: ``(parameters, coordinates)`` of a cheap, successful run.  Every registered
    forward model must override it (the base's gives None).
``example_options()``
    Any kind: the options (a dict) of a cheap instance for conformance runs, e.g. a coarse
    mesh, a measure length scale that suits the sample interfaces of :func:`measure_cases`,
    or a small number of particles (the base's: ``{}``).
``dims``, ``mesh_dependent``
    Measures: the spatial dimensions supported (the base's ``(2, 3)``), and whether the
    residuals belong to the simulated mesh (see :func:`check_measure`; the base's False).

Every member of every contract, with its role, default and docstring, read from the code:
:func:`fbia.testing.contracts.contracts`.

pytest loads only the fixtures of :mod:`fbia.pytest_plugin` at start-up; this module (numpy,
trimesh, the fbia sub-modules) is imported when a test uses it.
"""

from __future__ import annotations

from .errors import ConformanceError
from .install import PluginInstaller, write_dist_info
from .iterators import CountingEvaluator, check_iterator, tiny_problem
from .measures import MeasureCase, check_measure, measure_cases
from .models import check_forward_model, example_run
from .options import check_options, example_options
from .registered import check_registered, failing_run
from .samples import circle_2d, mound_2d, sphere_3d, square_3d, straight_line_2d

__all__ = [
    "ConformanceError",
    "CountingEvaluator",
    "MeasureCase",
    "PluginInstaller",
    "check_forward_model",
    "check_iterator",
    "check_measure",
    "check_options",
    "check_registered",
    "circle_2d",
    "example_options",
    "example_run",
    "failing_run",
    "measure_cases",
    "mound_2d",
    "sphere_3d",
    "square_3d",
    "straight_line_2d",
    "tiny_problem",
    "write_dist_info",
]
