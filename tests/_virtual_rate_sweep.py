"""A sweep kind that no gyrojax module knows, in one file: a rate table run with a constant virtual rate on
the virtual-Coriolis electrode (V_ac = `offset_v` at the fixed carrier while the table turns at each rate).
It checks that the Coriolis forces of a real and of a virtual rate add (test_sweeps), and that the planner
takes any registered kind as a candidate experiment (test_plan, with its own rates and dwell)."""

import numpy as np

import gyrojax as gj


class AbstractRateTableWithVirtualRate(gj.sweeps.AbstractSteadySweep):
    """What the kind is and how a point is applied; a final subclass names it and lists its inputs."""

    offset_v: float = 0.5

    title = "rate-table with a virtual rate"
    input_quantity = "table rate"
    input_unit = "deg/s"
    output_unit = "LSB"
    input_meaning = "the table rate, deg/s, with V_ac = 0.5 V on the virtual-Coriolis electrode"
    output_meaning = "the gyro's rate output, LSB"
    rate_input = True

    def check_device(self, gyro):
        if float(np.asarray(gyro.vcf_electrode.force_per_volt2)) == 0.0:
            raise ValueError(f"{self.name} needs a virtual-Coriolis electrode; {gyro.name!r} has none.")

    def stimulus(self, value, time):
        return gj.physics.Stimulus(rate=value * gj.units.DEG, vcf_ac=0.0 * value + self.offset_v,
                           vcf_fc=gj.sweeps.VCF_CARRIER_V, time=time)


class RateTableWithVirtualRate(AbstractRateTableWithVirtualRate):
    """At its own table rates (default seed 000's 22), the protocol's dwell and sampling."""

    rates_dps: tuple = gj.sweeps.points_field(gj.sweeps.DING_ZHOU_2025_RATES_DPS, "table rates (deg/s)")

    name = "rate_table_vcf_offset"
    stream = 101

    def inputs(self, gyro=None):
        return np.asarray(self.rates_dps)

    def n_points(self):
        return len(self.rates_dps)
