"""Control: drive PLL + AGC, force-to-rebalance (rate + quadrature) loop, open-loop readout."""
