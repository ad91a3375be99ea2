"""The energy ledger: running sums of the non-conservative work and the balance of every energy term.

Every history row holds ``kinetic``, ``strain``, ``gravity_potential`` ``-sum m g.(x - x_0)``,
``load_potential`` ``-sum f_ext.(x - x_0)``, ``damping_dissipation``, ``viscous_dissipation``,
``boundary_work`` (work done on the body by supports and prescribed velocities),
``interaction_work`` (work done on the body by the providers' forces, a cross-check), one
column per provider energy term, ``total = kinetic + strain + potentials + provider terms +
dissipations - boundary_work`` and ``balance_error = total - total at the first record``. With
the half-step bookkeeping of :mod:`fdem.kernels.stepping` the balance is exact for linear
forces; what remains measures nonlinearity, round-off and provider errors."""
from __future__ import annotations

__all__ = ["EnergyLedger", "work_halves"]


class EnergyLedger:
    """Running sums of the non-conservative work and the balance of all energy terms.

    Call :meth:`add_step` after every step with the kernel sums, :meth:`record` on ledger steps.
    Terms are named; providers add theirs (any names) through ``energy_terms()``.
    """

    CUMULATIVE = ("damping_dissipation", "viscous_dissipation", "boundary_work", "interaction_work")

    def __init__(self, gravity_moment0: float, external_moment0: float, roundoff: float = 0.0):
        """``*_moment0``: ``sum m g . x_0`` and ``sum f_ext . x_0`` [J/m]; ``roundoff``: the
        smallest energy scale [J/m] worth resolving (round-off floor of the potentials)."""
        self.gravity_moment0 = gravity_moment0
        self.external_moment0 = external_moment0
        self.roundoff = roundoff
        self.done = dict.fromkeys(self.CUMULATIVE, 0.0)  # sums over completed steps
        # Potential energy added by changing gravity at fixed positions (Simulation.set_gravity):
        # work done on the system by whoever changes g, booked like boundary work.
        self.gravity_change_work = 0.0
        # Kinetic energy added by changing the inertial masses at fixed velocities
        # (Simulation.set_density_scaling), booked the same way.
        self.mass_change_work = 0.0
        # Kinetic energy removed by setting the velocities of a region that falls asleep to zero
        # (fdem.solve.sleeping), booked as dissipated like damping work.
        self.sleep_dissipation = 0.0
        self.first_early: dict[str, float] | None = None
        self.total0: float | None = None
        self.scale = 0.0
        self.last: dict[str, float] = {}

    def cumulative(self, early: dict[str, float]) -> dict[str, float]:
        """Cumulative values at step n, given step n's early halves (see the kernel docstring)."""
        if self.first_early is None:
            self.first_early = dict(early)
        return {k: self.done[k] + early[k] - self.first_early[k] for k in self.CUMULATIVE}

    def add_step(self, early: dict[str, float], late: dict[str, float]) -> None:
        if self.first_early is None:
            self.first_early = dict(early)
        for k in self.CUMULATIVE:
            self.done[k] += early[k] + late[k]

    def record(self, kinetic: float, strain: float, gravity_moment: float, external_moment: float,
               early: dict[str, float], provider_terms: dict[str, float], providers_complete: bool) -> dict[str, float]:
        c = self.cumulative(early)
        row = {"kinetic": kinetic, "strain": strain,
               "gravity_potential": -(gravity_moment - self.gravity_moment0),
               "load_potential": -(external_moment - self.external_moment0)}
        row.update(c)
        row.update(provider_terms)
        held = row["kinetic"] + row["strain"] + row["gravity_potential"] + row["load_potential"]
        spent = row["damping_dissipation"] + row["viscous_dissipation"] + self.sleep_dissipation
        interactions = sum(provider_terms.values()) if providers_complete else -row["interaction_work"]
        row["gravity_change_work"] = self.gravity_change_work
        row["mass_change_work"] = self.mass_change_work
        row["sleep_dissipation"] = self.sleep_dissipation
        total = (held + spent + interactions - row["boundary_work"] - self.gravity_change_work
                 - self.mass_change_work)
        if self.total0 is None:
            self.total0 = total
        size = (abs(row["kinetic"]) + abs(row["strain"]) + abs(row["gravity_potential"]) + abs(row["load_potential"])
                + abs(spent) + abs(row["boundary_work"]) + abs(self.gravity_change_work)
                + abs(self.mass_change_work)
                + sum(abs(t) for t in provider_terms.values()))
        self.scale = max(self.scale, size, self.roundoff)
        row["total"] = total
        row["balance_error"] = total - self.total0
        row["balance_error_relative"] = row["balance_error"] / self.scale if self.scale > 0 else 0.0
        self.last = row
        return row


def work_halves(sums) -> tuple[dict[str, float], dict[str, float]]:
    """The early and late halves of one step's non-conservative work (from a
    :class:`~fdem.kernels.stepping.StepSums`), keyed by the ledger's cumulative columns."""
    early = {"damping_dissipation": sums.damping_early, "viscous_dissipation": sums.viscous_early,
             "boundary_work": sums.reaction_early, "interaction_work": sums.interaction_early}
    late = {"damping_dissipation": sums.damping_late, "viscous_dissipation": sums.viscous_late,
            "boundary_work": sums.reaction_late, "interaction_work": sums.interaction_late}
    return early, late
