"""The fbia plugin module of fbia-mysolver: a forward model that runs an external solver.

Use it like any forward model, once the package is installed::

    model = fbia.forward_model("mysolver", timeout=30.0, command=["mysolver", "{input}"])
    solution = model.solve({"E": 400.0, "nu": 0.3}, [{"inflow_rate": 100.0}], workdir)

Every run happens in the folder fbia gives it (``workdir``):

1. write ``mysolver_input.json`` with the parameters, the solver settings and, for every
   requested state, its coordinate and the name of the CSV file to write;
2. run ``command`` there (``{input}`` in an argument is replaced by the input file's path),
   with ``timeout`` seconds to finish; stdout and stderr go to ``mysolver.log``;
3. read each state's interface CSV (``x, y`` per row, upstream to downstream, in mm).

A non-zero exit status, a time-out, a missing or unreadable output file: each is a failed run,
:class:`fbia.ForwardModelError` with the last lines of the solver's stderr, which fbia records
and the iterator handles (e.g. Levenberg-Marquardt shortens its step).  A command that does not
exist is a :class:`fbia.ConfigError` when the model is built, before any run.
"""

from __future__ import annotations

import json
import os
import shutil
import subprocess
import sys
from collections.abc import Mapping, Sequence
from pathlib import Path

import fbia
from pydantic import Field, field_validator

#: The bundled stand-in solver, run with the Python that runs fbia.
BUNDLED_SOLVER = Path(__file__).with_name("external_solver.py")
INPUT_FILE = "mysolver_input.json"
LOG_FILE = "mysolver.log"


class MySolverForwardModel(fbia.ForwardModelBase):
    """Runs an external solver per forward evaluation (see the module docstring)."""

    class Options(fbia.PluginOptions):
        command: list[str] | None = Field(
            None,
            min_length=1,
            description="solver command and arguments; '{input}' in an argument becomes the "
            "input JSON's path; None: the bundled stand-in (python external_solver.py {input})",
        )
        timeout: float = Field(60.0, gt=0, description="wall-clock limit of one run [s]")
        n_points: int = Field(61, ge=3, description="points of the solver's interface [-]")
        env: dict[str, str] = Field(
            default_factory=dict,
            description="extra environment variables of the solver, e.g. OMP_NUM_THREADS",
        )
        stderr_lines: int = Field(
            10, ge=1, description="lines of the solver's stderr quoted in an error [-]"
        )

        @field_validator("command")
        @classmethod
        def _executable_exists(cls, command: list[str] | None) -> list[str] | None:
            if command and shutil.which(command[0]) is None and not Path(command[0]).is_file():
                raise ValueError(f"solver executable {command[0]!r} not found")
            return command

    options: Options

    @classmethod
    def example_parameters(cls) -> tuple[dict[str, float], list[dict[str, float]]]:
        """A cheap, successful run for conformance tests (fbia.testing)."""
        return {"E": 400.0, "nu": 0.3}, [{"inflow_rate": 50.0}, {"inflow_rate": 100.0}]

    def parameter_names(self) -> Sequence[str]:
        """``E`` [Pa] and ``nu`` [-]."""
        return ("E", "nu")

    def command(self, input_file: Path) -> list[str]:
        base = self.options.command or [sys.executable, str(BUNDLED_SOLVER), "{input}"]
        return [arg.replace("{input}", str(input_file)) for arg in base]

    def solve(
        self,
        parameters: Mapping[str, float],
        coordinates: Sequence[Mapping[str, float]],
        workdir: Path,
    ) -> fbia.Solution:
        """Run the solver once for all ``coordinates``; one interface per coordinate."""
        workdir = Path(workdir).resolve()
        workdir.mkdir(parents=True, exist_ok=True)
        values = {"E": 400.0, "nu": 0.3, **{k: float(v) for k, v in parameters.items()}}
        states = [
            {"coordinate": dict(c), "output": f"interface_{k:03d}.csv"}
            for k, c in enumerate(coordinates)
        ]
        input_file = workdir / INPUT_FILE
        job = {"parameters": values, "settings": {"n_points": self.options.n_points}}
        input_file.write_text(json.dumps({**job, "states": states}, indent=1))
        cmd = self.command(input_file)
        try:
            run = subprocess.run(
                cmd,
                cwd=workdir,
                capture_output=True,
                text=True,
                timeout=self.options.timeout,
                env={**os.environ, **self.options.env},
                check=False,
            )
        except subprocess.TimeoutExpired as exc:
            self._log(workdir, exc.stdout, exc.stderr)
            raise fbia.ForwardModelError(
                f"mysolver timed out after {self.options.timeout:g} s{self._tail(exc.stderr)}",
                reason="timeout",
            ) from None
        self._log(workdir, run.stdout, run.stderr)
        if run.returncode != 0:
            raise fbia.ForwardModelError(
                f"mysolver exited with status {run.returncode}{self._tail(run.stderr)}",
                reason="solver_failed",
            )
        pairs = []
        for c, state in zip(coordinates, states, strict=True):
            path = workdir / state["output"]
            if not path.is_file():
                raise fbia.ForwardModelError(
                    f"mysolver wrote no {state['output']} for {dict(c)}{self._tail(run.stderr)}",
                    reason="no_output",
                )
            try:
                pairs.append((c, fbia.Interface.read(path)))
            except fbia.ConfigError as exc:
                raise fbia.ForwardModelError(
                    f"mysolver wrote an unreadable interface: {exc}", reason="bad_output"
                ) from None
        return fbia.Solution.from_pairs(pairs, diagnostics={"command": cmd})

    def _tail(self, stderr: str | bytes | None) -> str:
        if not stderr:
            return ""
        text = stderr.decode(errors="replace") if isinstance(stderr, bytes) else stderr
        lines = text.strip().splitlines()[-self.options.stderr_lines :]
        return "; stderr: " + " | ".join(lines) if lines else ""

    @staticmethod
    def _log(workdir: Path, stdout: str | bytes | None, stderr: str | bytes | None) -> None:
        def text(s: str | bytes | None) -> str:
            return s.decode(errors="replace") if isinstance(s, bytes) else (s or "")

        (workdir / LOG_FILE).write_text(f"# stdout\n{text(stdout)}\n# stderr\n{text(stderr)}")


@fbia.hookimpl
def register_forward_models(register):  # type: ignore[no-untyped-def]
    """Make ``fbia.forward_model("mysolver")`` build :class:`MySolverForwardModel`."""
    register("mysolver", MySolverForwardModel)
