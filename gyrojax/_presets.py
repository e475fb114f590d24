"""Device presets. Every number says where it comes from: a seed table, or an assumption and why.

Seed 000 = Ding & Zhou, Micromachines 2025, 16, 851 (closed-loop quad-mass gyroscope, "QMG").
Seed 003 = the virtual-Coriolis-force batch calibration paper (open-loop z-axis gyroscope, 13 devices).
"""

import cmath
import math

import jax.numpy as jnp

from ._control.openloop import OpenLoopReadout
from ._electronics.dac import DAC
from ._electronics.excitation import FTRExcitation
from ._electronics.frontend import FrontEnd
from ._gyroscope import Gyroscope, design_drive_loop, design_rebalance_loop
from ._lots.stack import as_arrays
from ._physics.electrodes import DriveElectrode, FeedbackElectrode, VirtualCoriolisElectrode
from ._physics.resonator import Resonator
from ._units import DEG, hz_to_rad_s


# --- seed 000 (paper-qmg) -----------------------------------------------------------------------------
QMG_MASS = 1.56e-6  # kg, Table 1 "Mass 1.56 mg"
QMG_FX = 4634.0  # Hz, Table 1 drive frequency
QMG_FY_AS_BUILT = 4711.0  # Hz, Table 1 sense frequency (77 Hz split, as built)
QMG_RESIDUAL_SPLIT = 1.0  # Hz, ASSUMPTION: §5 tunes the split out with an open-loop voltage; residual not given
QMG_QX = 1.02e6  # Table 1
QMG_QY = 0.34e6  # Table 1
QMG_KVI_X = 2.41e-6  # A/(m/s), Table 1 velocity-to-current factor (X)
QMG_KVI_Y = 6.61e-6  # A/(m/s), Table 1 velocity-to-current factor (Y)
QMG_KDX = 2.79e-9  # N/V, Table 1 voltage-to-force factor (X): gives a drive voltage of ~2.4 V, plausible
QMG_KVF_PRINTED = 4.52e-9  # N/V, Table 1 voltage-to-force factor (Y): does NOT close, see below
QMG_SF = 13709.853  # LSB/(deg/s), Table 3 / §5, uncompensated scale factor
QMG_AMPLITUDE = 5e-6  # m, ASSUMPTION: a typical drive amplitude for a 4.6 kHz, 1.56 mg QMG (not printed)
QMG_ANGULAR_GAIN = 1.0  # ASSUMPTION: Table 1's equivalent mass taken as the Coriolis mass (Ag not printed)
QMG_AMPLIFIER_GAIN = 1.0  # ASSUMPTION: Fig. 5's K_a not printed; Table 2's Vac taken as the FTR AC voltage
QMG_VDC = 10.0  # V, ASSUMPTION: feedback bias (not printed; sets only the push-pull / gap terms)
QMG_GAP = 2.0e-6  # m, ASSUMPTION: finger-tip gap d0 of the FTR combs (Eq. 5-7; not printed)
QMG_CHARGE_GAIN = 1.0e11  # V/C, ASSUMPTION: 1/C_f with C_f = 10 pF (a charge-sensing front end, see below)
QMG_ADC_LSB = 5.0 / 2**24  # V, ASSUMPTION: the "24-bit high-precision ADC" of §5 on a +/-2.5 V range
QMG_DAC_UPDATE_RATE = 1.0e6  # Hz, ASSUMPTION: DAC update rate (not printed)
QMG_INL_TERMS = 4  # ASSUMPTION: an ideal DAC with four zero INL terms (u^2..u^5), so that the dac_inl effect
#                    adds into them without changing the leaf's shape (one compiled function for both)
QMG_QUADRATURE_DPS = 10.0  # deg/s, ASSUMPTION: residual quadrature of a symmetric QMG, expressed as the rate
#                            whose Coriolis force it equals: kap = 2 Ag w_x x 10 deg/s. Seed 000 runs a
#                            quadrature loop (Fig. 8) but prints no level; every real device has some, and a
#                            phase error of the rate channel (quadrature_phase) needs it to act on
QMG_VCF_DPS_PER_V2 = 100.0  # deg/s per V^2 of V_ac V_fc, ASSUMPTION: seed 000 has no virtual-Coriolis
#                             electrode; a self-test electrode like seed 003's, sized so that V_fc = 1 V and
#                             V_ac = +/-2 V span +/-200 deg/s. Closed-loop VCF sweeps separate a drift of
#                             the feedback gain (vref_drift) from one of the drive frequency (thermal_drift)
SILICON_TCF = -30e-6  # 1/K, silicon resonators, about -30 ppm/K (the physics, docs/physics.md)
SILICON_TCQ = -3e-3  # 1/K, ASSUMPTION: Q ~ 1/T_abs near room temperature (thermoelastic and gas damping both
#                      grow with temperature): -1/(298 K) = -3.4e-3/K, rounded. It moves no settled output of
#                      the ideal loops; a finite-gain AGC (agc_finite_gain) turns it into a gain drift

# The closed-loop scale factor is SF = 2 Ag m a w / (K_vf K_a kappa) with kappa = 5 V / 2^23 per word LSB
# (Table 2: 0x29E345 = 2,745,157 LSB -> 1.637 V). Keeping the measured SF (13,709.853 LSB/(deg/s)) and the
# assumed a, Ag and K_a, the feedback factor must be K_vf = 9.70e-7 N/V: 215 times Table 1's printed
# 4.52e-9 N/V. Conversely, the printed K_vf would need a drive amplitude of a = 23 nm (or K_a = 215, i.e.
# 352 V of feedback at 200 deg/s on a +/-15 V analog board). The printed factor cannot close with a
# plausible drive amplitude; the preset keeps the measured SF and Vac and derives K_vf.
QMG_DAC_VOLTS_PER_LSB = 5.0 / 2**23


def _qmg_kvf():
    omega = hz_to_rad_s(QMG_FX)
    sf_rad = QMG_SF / DEG
    half_angle = 0.5 * omega / QMG_DAC_UPDATE_RATE  # the DAC hold's sinc gain is part of the chain
    hold_gain = math.sin(half_angle) / half_angle
    return 2.0 * QMG_ANGULAR_GAIN * QMG_MASS * QMG_AMPLITUDE * omega / (
        QMG_AMPLIFIER_GAIN * QMG_DAC_VOLTS_PER_LSB * hold_gain * sf_rad)


def paper_qmg(**resonator_overrides: float) -> Gyroscope:
    """The closed-loop (force-to-rebalance) quad-mass gyroscope of seed 000.

    Table 1 gives the mechanics; Table 2 the DAC scale (16-bit, +/-5 V, 24-bit word); §5 the scale factor
    13,709.853 LSB/(deg/s) over +/-200 deg/s. Unknowns (drive amplitude, angular gain, amplifier gain,
    bias, gaps, front-end and ADC scaling, DAC update rate, loop bandwidths) are assumptions listed in
    `gyrojax/_presets.py`; K_vf is derived from the measured SF (the printed 4.52e-9 N/V does not close).

    The front end is charge-sensing (an AGC holding displacement amplitude): seed 000's Eq. (2) and its
    initial calibration SF_new = SF k_t / w_x assume that SF tracks the drive frequency, which holds only
    if the AGC holds a, not a w.
    """
    omega_x = hz_to_rad_s(QMG_FX)
    resonator_args = dict(
        mass=QMG_MASS,
        omega_x=omega_x,
        omega_y=hz_to_rad_s(QMG_FX + QMG_RESIDUAL_SPLIT),
        q_x=QMG_QX,
        q_y=QMG_QY,
        angular_gain=QMG_ANGULAR_GAIN,
        stiffness_coupling=2.0 * QMG_ANGULAR_GAIN * omega_x * QMG_QUADRATURE_DPS * DEG,
        tcf=SILICON_TCF,
        tcq=SILICON_TCQ,
    )
    resonator = Resonator(**(resonator_args | resonator_overrides))
    drive_electrode = DriveElectrode(QMG_KDX)
    drive_frontend = FrontEnd(QMG_KVI_X, QMG_CHARGE_GAIN, QMG_ADC_LSB, kind="charge")
    sense_frontend = FrontEnd(QMG_KVI_Y, QMG_CHARGE_GAIN, QMG_ADC_LSB, kind="charge")
    feedback = FeedbackElectrode(k_vf=_qmg_kvf(), v_dc=QMG_VDC, gap=QMG_GAP)
    excitation = FTRExcitation(DAC(full_scale=5.0, bits=16, word_bits=24, update_rate=QMG_DAC_UPDATE_RATE,
                                   inl=jnp.zeros(QMG_INL_TERMS)),
                               amplifier_gain=QMG_AMPLIFIER_GAIN)
    vcf = VirtualCoriolisElectrode(2.0 * QMG_MASS * QMG_ANGULAR_GAIN * QMG_AMPLITUDE * omega_x
                                   * QMG_VCF_DPS_PER_V2 * DEG)
    # ASSUMPTION: loop designs (not printed): PLL and AGC at 20 Hz (critically damped), FTR at 100 Hz
    # (zeta 0.7), demodulator LPFs four first-order stages at 1 kHz: the 2w ripple is -78 dB. What is left
    # of it, through the AGC's proportional gain, puts a 2w ripple on the drive voltage whose product with
    # the carrier pushes a little force in phase with the displacement: the full waveform then locks
    # 0.24 ppm above resonance and its SF reads 0.23 ppm above the averaged tiers (which drop the ripple).
    # Two stages would leave 34 ppm (the ripple^2/4 bias of the AGC's mean |e_d|).
    drive_loop = design_drive_loop(resonator, drive_electrode, drive_frontend, amplitude=QMG_AMPLITUDE,
                                   pll_bandwidth=hz_to_rad_s(20.0), agc_bandwidth=hz_to_rad_s(20.0),
                                   demod_cutoff=hz_to_rad_s(1000.0))
    rebalance = design_rebalance_loop(resonator, feedback, excitation, sense_frontend,
                                      bandwidth=hz_to_rad_s(100.0), demod_cutoff=hz_to_rad_s(1000.0))
    return as_arrays(Gyroscope(
        resonator=resonator,
        drive_electrode=drive_electrode,
        drive_frontend=drive_frontend,
        sense_frontend=sense_frontend,
        drive_loop=drive_loop,
        feedback_electrode=feedback,
        excitation=excitation,
        rebalance_loop=rebalance,
        vcf_electrode=vcf,
        name="paper-qmg",
    ))


# --- seed 003 (vcf-2018) ------------------------------------------------------------------------------
VCF_MASS = 9.740e-8  # kg, Table 1 "md(g) 9.740x10-8": read as kg (97 ug); in grams the VCF rate of
#                      Eq. 7 would be ~1000x too large for Vac = 20 mV
VCF_DRIVE_VELOCITY = 0.206  # m/s, Table 1 "x w_d" -> a = 18.2 um
VCF_KSVF = 2.14e-5  # N/V, Table 1 (force per volt of V_ac at the V_fc of the test), used as N/V^2
VCF_WD = 11330.0  # rad/s, Table 2
VCF_WS = 11715.0  # rad/s, Table 2
VCF_QS = 9824.0  # Table 2
VCF_QD = 9824.0  # ASSUMPTION: drive Q not printed; taken equal to the sense Q (same die, same vacuum)
VCF_SF_V_PER_DPS = 0.104e-3  # V/(deg/s), §3: conventional rate-table scale factor
VCF_LPF_HZ = 2000.0  # Hz, §3: "LMF is a lowpass filter with stop frequency 2000 Hz"
VCF_ADC_LSB = 2.0 / 2**16  # V, ASSUMPTION: NI DAQ 6366 (16-bit) on its +/-1 V range
VCF_KYI = 1.0e-6  # A/(m/s), ASSUMPTION: pick-off factor (not printed; only the product with K_iv matters)


def vcf_2018(**resonator_overrides: float) -> Gyroscope:
    """The open-loop z-axis gyroscope of seed 003 (Tables 1-2), with its virtual-Coriolis electrode.

    The readout gain is chosen so that the rate-table scale factor is the measured 0.104 mV/(deg/s) at the
    nominal point. Seed 003's band-pass filter ("15000 Hz to 22000 Hz") would reject its own 1.8 kHz drive
    carrier, so it is not modelled; the 2 kHz LPF is. Seed 003 reports a 354.3 Hz measured and 349.5 Hz
    simulated rate bandwidth; the model with Table 2's numbers gives about 97 Hz (1.55 x the 62 Hz
    split); see `experiments/seed_closure.py`.
    """
    resonator = Resonator(**(dict(mass=VCF_MASS, omega_x=VCF_WD, omega_y=VCF_WS, q_x=VCF_QD, q_y=VCF_QS,
                                  angular_gain=1.0, tcf=SILICON_TCF, tcq=SILICON_TCQ) | resonator_overrides))
    a = VCF_DRIVE_VELOCITY / VCF_WD
    gy = VCF_WS / (2 * VCF_QS)
    dy = (VCF_WS**2 - VCF_WD**2) / (2 * VCF_WD)
    # Sense displacement per rad/s at DC: Ag a / |g_y - j d_y|; output volts = gain * K_yi * that.
    sense_gain = (VCF_SF_V_PER_DPS / DEG) / (VCF_KYI * a / math.hypot(gy, dy))
    drive_frontend = FrontEnd(VCF_KYI, sense_gain, VCF_ADC_LSB, kind="charge")
    sense_frontend = FrontEnd(VCF_KYI, sense_gain, VCF_ADC_LSB, kind="charge")
    # ASSUMPTION: drive electrode factor 1e-7 N/V (not printed; sets only the drive voltage level).
    drive_electrode = DriveElectrode(1e-7)
    # ASSUMPTION: drive loop as for paper-qmg, with its demodulator LPF at 200 Hz (the 2 kHz LPF of the
    # paper is the rate output's; on the drive loop it would pass the 3.6 kHz ripple almost untouched).
    drive_loop = design_drive_loop(resonator, drive_electrode, drive_frontend, amplitude=a,
                                   pll_bandwidth=hz_to_rad_s(20.0), agc_bandwidth=hz_to_rad_s(20.0),
                                   demod_cutoff=hz_to_rad_s(200.0))
    # Demodulation phase aligned with the Coriolis response at zero rate: Y = -Ag Om a / (g_y - j d_y).
    coriolis_phase = cmath.phase(-1.0 / (gy - 1j * dy))
    # ASSUMPTION: the 2 kHz output LPF as two first-order stages.
    readout = OpenLoopReadout(demod_cutoff=hz_to_rad_s(VCF_LPF_HZ), reference_phase=coriolis_phase,
                              demod_order=2)
    return as_arrays(Gyroscope(
        resonator=resonator,
        drive_electrode=drive_electrode,
        drive_frontend=drive_frontend,
        sense_frontend=sense_frontend,
        drive_loop=drive_loop,
        readout=readout,
        vcf_electrode=VirtualCoriolisElectrode(VCF_KSVF),
        name="vcf-2018",
    ))


PRESETS = {"paper-qmg": paper_qmg, "vcf-2018": vcf_2018}


def preset(name: str) -> Gyroscope:
    """A preset device by name: `"paper-qmg"` (seed 000) or `"vcf-2018"` (seed 003)."""
    try:
        return PRESETS[name]()
    except KeyError:
        raise ValueError(f"unknown preset {name!r}; expected one of {sorted(PRESETS)}.") from None
