"""The composite device: resonator, electrodes, electronics and loops, as one differentiable PyTree."""

from typing import NamedTuple

import equinox as eqx
import jax.numpy as jnp
from jaxtyping import Array, ArrayLike, Float

from ._control.drive import DriveLoop
from ._control.openloop import OpenLoopReadout
from ._control.rebalance import RebalanceLoop
from ._electronics.excitation import FTRExcitation
from ._electronics.frontend import FrontEnd
from ._physics.electrodes import DriveElectrode, FeedbackElectrode, VirtualCoriolisElectrode
from ._physics.resonator import Resonator
from ._physics.thermal import AbstractTemperature, ConstantTemperature
from ._terms import AbstractFeedbackTerm, AbstractTerm, TemperatureCoefficient, check_path


class Gyroscope(eqx.Module):
    """A MEMS Coriolis vibratory gyroscope with its drive loop and either a force-to-rebalance loop
    (closed loop, seed 000) or an open-loop readout (seed 003).

    Every array field is a differentiable parameter; change one with `eqx.tree_at`, never in place.
    `phase_points` is how many carrier phases the averaged and steady tiers use to take the fundamental
    (the describing function) of the nonlinear forces. N phases give the fundamental of a force polynomial
    in the carrier phase exactly up to degree N - 2; the default 16 covers a DAC INL up to u^7 squared by
    the push-pull combs (degree 14). Measured: 16 and 64 agree within 7e-10 ppm of full scale on the rate
    sweep of both presets, with every effect at 1x and 4x its typical size, and the steady tier runs ~4x
    faster. A DAC with DNL (a sawtooth in the code, not band-limited) needs many more (256+).

    `terms` holds the slots for new physics (`gyrojax.AbstractRateTerm`, `AbstractFeedbackTerm`,
    `AbstractOutputTerm`, `TemperatureCoefficient`): terms the fixed parts cannot express, each evaluated
    where it acts. Add one with `with_term`.
    """

    resonator: Resonator
    drive_electrode: DriveElectrode
    drive_frontend: FrontEnd
    sense_frontend: FrontEnd
    drive_loop: DriveLoop
    feedback_electrode: FeedbackElectrode | None = None
    excitation: FTRExcitation | None = None
    rebalance_loop: RebalanceLoop | None = None
    readout: OpenLoopReadout | None = None
    vcf_electrode: VirtualCoriolisElectrode = VirtualCoriolisElectrode(0.0)
    temperature: AbstractTemperature = ConstantTemperature()
    terms: tuple[AbstractTerm, ...] = ()
    phase_points: int = eqx.field(static=True, default=16)
    name: str = eqx.field(static=True, default="custom")

    def __check_init__(self):
        closed = self.rebalance_loop is not None
        if closed and (self.feedback_electrode is None or self.excitation is None):
            raise ValueError("Gyroscope: a rebalance_loop needs a feedback_electrode and an excitation.")
        if closed == (self.readout is not None):
            raise ValueError("Gyroscope: give exactly one of rebalance_loop (closed loop) or readout (open loop).")
        if not isinstance(self.phase_points, int) or self.phase_points < 8:
            raise ValueError(f"Gyroscope.phase_points must be an integer >= 8, got {self.phase_points!r}.")

    @property
    def closed_loop(self) -> bool:
        return self.rebalance_loop is not None

    def with_term(self, term: AbstractTerm) -> "Gyroscope":
        """A new device with `term` appended to its `terms` slot."""
        if not isinstance(term, AbstractTerm):
            raise ValueError(f"Gyroscope.with_term expects a gyrojax term (AbstractRateTerm, AbstractFeedbackTerm, "
                             f"AbstractOutputTerm or TemperatureCoefficient), got {type(term).__name__}.")
        if isinstance(term, TemperatureCoefficient):
            check_path(self, term.path)
        return eqx.tree_at(lambda g: g.terms, self, self.terms + (term,))

    def terms_of(self, kind: type[AbstractTerm]) -> tuple:
        """The terms of one kind (a class), in the order they were added."""
        return tuple(t for t in self.terms if isinstance(t, kind))

    def at_die_temperature(self, temperature: Float[ArrayLike, ""]) -> "Gyroscope":
        """The device with every `TemperatureCoefficient` applied at die `temperature` (deg C); the
        resonator's own coefficients (`Resonator.at_temperature`) act where the frequencies are used."""
        gyro = self
        for term in self.terms_of(TemperatureCoefficient):
            gyro = term.scaled(gyro, temperature)
        return gyro

    def feedback_voltages(self, dac_voltage: Float[Array, "*sample"]
                          ) -> tuple[Float[Array, "*sample"], Float[Array, "*sample"]]:
        """AC voltages of the + and - feedback branches for instantaneous DAC output samples (V): the
        amplifier K_a, then every `AbstractFeedbackTerm` in order, then the branch split."""
        def after_amplifier(v):
            for term in self.terms_of(AbstractFeedbackTerm):
                v = term(self, v)
            return v

        return closed_loop_parts(self, "feedback_voltages").excitation.branch_voltages(dac_voltage, after_amplifier)

    def rebalance_gain(self, omega: float | Float[Array, ""]) -> Float[Array, ""]:
        """Linear rebalance force per word LSB at the carrier, N/LSB, including the DAC hold gain."""
        feedback, excitation, _ = closed_loop_parts(self, "rebalance_gain")
        dac = excitation.dac
        hold_gain, _ = dac.hold(omega)
        return (feedback.k_vf * excitation.amplifier_gain * dac.volts_per_word_lsb
                * (1.0 + dac.gain_error) * hold_gain)

    def ideal_scale_factor(self, temperature: Float[ArrayLike, ""] | None = None) -> Float[Array, ""]:
        """Seed 000 Eq. (2) in output LSB per rad/s: SF = 2 Ag m a w / K_vf (closed loop, linear chain).

        `a` is the drive amplitude that the AGC's set point means through the drive front end, and w the
        drive resonance at `temperature` (default: the resonator's reference temperature).
        """
        r = self.resonator
        t = r.t_ref if temperature is None else temperature
        omega, _, _, _ = r.at_temperature(t)
        a = self.drive_amplitude(omega)
        return 2.0 * r.angular_gain * r.mass * a * omega / self.rebalance_gain(omega)

    def drive_amplitude(self, omega: Float[ArrayLike, "*omega"]) -> Float[Array, "*omega"]:
        """Drive displacement amplitude (m) that the AGC set point stands for at frequency `omega`."""
        return self.drive_loop.amplitude_setpoint / jnp.abs(self.drive_frontend.phasor_gain(omega))


def design_drive_loop(resonator: Resonator, electrode: DriveElectrode, frontend: FrontEnd, *, amplitude: float,
                      pll_bandwidth: float, agc_bandwidth: float, demod_cutoff: float, damping: float = 1.0
                      ) -> DriveLoop:
    """Drive-loop gains placing the PLL's and the AGC's closed-loop poles at the given natural
    frequencies (rad/s) with the given damping, for a drive mode at resonance.

    The envelope plant is |X|' = -g |X| + K_dx V_d / (2 w m) for the AGC and phase' = w_x - w for the PLL,
    so both loops with a PI controller are second-order: s^2 + 2 zeta wn s + wn^2.
    """
    omega = resonator.omega_x
    g = jnp.abs(frontend.phasor_gain(omega))
    b = electrode.force_per_volt / (2.0 * omega * resonator.mass) * g
    return DriveLoop(
        amplitude_setpoint=amplitude * g,
        center_frequency=omega,
        pll_kp=2.0 * damping * pll_bandwidth,
        pll_ki=pll_bandwidth**2,
        agc_kp=2.0 * damping * agc_bandwidth / b,
        agc_ki=agc_bandwidth**2 / b,
        demod_cutoff=demod_cutoff,
        reference_phase=jnp.angle(frontend.phasor_gain(omega)),
    )


def design_rebalance_loop(resonator: Resonator, feedback: FeedbackElectrode, excitation: FTRExcitation,
                          frontend: FrontEnd, *, bandwidth: float, demod_cutoff: float, damping: float = 0.7
                          ) -> RebalanceLoop:
    """Rebalance gains placing the sense loop's poles at s^2 + 2 zeta wn s + wn^2 (mode-matched design),
    with the carrier advanced by the DAC hold delay at the drive resonance."""
    omega = resonator.omega_x
    dac = excitation.dac
    hold_gain, hold_delay = dac.hold(omega)
    gain = feedback.k_vf * excitation.amplifier_gain * dac.volts_per_word_lsb * hold_gain
    b = gain / (2.0 * omega * resonator.mass) * jnp.abs(frontend.phasor_gain(omega))
    return RebalanceLoop(
        kp=2.0 * damping * bandwidth / b,
        ki=bandwidth**2 / b,
        demod_cutoff=demod_cutoff,
        reference_phase=jnp.angle(frontend.phasor_gain(omega)),
        carrier_phase=hold_delay,
    )


class ClosedLoopParts(NamedTuple):
    feedback_electrode: FeedbackElectrode
    excitation: FTRExcitation
    rebalance_loop: RebalanceLoop


def closed_loop_parts(gyro: Gyroscope, what: str) -> ClosedLoopParts:
    """The force-to-rebalance parts of a closed-loop device; a ValueError naming `what` for an open-loop one."""
    feedback, excitation, loop = gyro.feedback_electrode, gyro.excitation, gyro.rebalance_loop
    if feedback is None or excitation is None or loop is None:
        raise ValueError(f"{what} needs a closed-loop device (feedback_electrode, excitation and rebalance_loop); "
                         f"{gyro.name!r} is open loop.")
    return ClosedLoopParts(feedback, excitation, loop)


def open_loop_readout(gyro: Gyroscope, what: str) -> OpenLoopReadout:
    """The readout of an open-loop device; a ValueError naming `what` for a closed-loop one."""
    if gyro.readout is None:
        raise ValueError(f"{what} needs an open-loop device (a readout); {gyro.name!r} is closed loop.")
    return gyro.readout
