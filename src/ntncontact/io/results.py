"""The observer that writes a run folder: history every step, fields at output times."""

from __future__ import annotations

from pathlib import Path

from ..model import Model
from ..postprocess import element_von_mises
from ..simulation import StepRecord
from .writers import ResultsDirectory


class ResultWriter:
    """Writes history.csv, summary.json and fields.pvd/VTU as the simulation advances."""

    def __init__(self, directory: str | Path, model: Model, extra_history: tuple[str, ...] = (),
                 **summary_extra: object) -> None:
        self.results = ResultsDirectory(directory, history_columns=extra_history,
                                        **summary_extra)
        self.model = model
        self.extra_history = extra_history
        self.interval = model.analysis.output_interval
        self._next_output = 0.0
        self._body_id = model.body_of_cell().astype(float)

    def on_step(self, model: Model, record: StepRecord) -> None:
        s, b = record.state, record.balance
        row = {
            "step": s.step, "time": s.time,
            "kinetic_energy": b.kinetic_energy, "strain_energy": b.strain_energy,
            "total_energy": b.total_energy,
            "linear_momentum_x": b.linear_momentum[0], "linear_momentum_y": b.linear_momentum[1],
            "angular_momentum": b.angular_momentum,
            "newton_iterations": record.newton_iterations,
        }
        row |= {k: record.extra.get(k, 0.0) for k in self.extra_history}
        self.results.write_history(row)
        if self._due(s.time, model):
            self._write_fields(model, record)

    def _due(self, time: float, model: Model) -> bool:
        last = time >= model.analysis.t_end - 1e-9 * model.analysis.dt
        if self.interval is None or last or time >= self._next_output - 1e-9 * model.analysis.dt:
            if self.interval is not None:
                self._next_output = time + self.interval
            return True
        return False

    def _write_fields(self, model: Model, record: StepRecord) -> None:
        if self.results.fields is None:
            return
        s = record.state
        vm = element_von_mises(model, s.X, s.x)
        self.results.fields.write(
            s.step, s.time, s.X, model.cells,
            point_data={"displacement": s.d, "velocity": s.v, "acceleration": s.a},
            cell_data={"von_mises": vm, "body_id": self._body_id},
        )

    def on_finish(self, status: str, error: str | None) -> None:
        self.results.close()
        self.results.summary.finish(status, error)

    def update_summary(self, **fields: object) -> None:
        self.results.summary.update(**fields)

