"""The lot as a population: chosen per-device parameters are random effects drawn from a lot distribution whose
mean and spread are estimated with them (empirical Bayes, as nlmixr2, Monolix and Pumas do for subjects).

The method (`population_fit`), in the coordinates the fit uses (theta = log p for `"log"` parameters, p / scale
for `"linear"` ones), with a diagonal lot covariance Omega = diag(s^2):

1. Every device is fitted (vmapped, `VmapSolve`) with a Gaussian prior N(mu, Omega) on its random parameters; the
   first prior is weak (`start_spread` around the start value), so that every device's fit is determined.
2. From each fit, the data's own information about the random parameters (the prior rows left out, every other
   free parameter profiled out: the Schur complement of the weighted Jacobian) J_i and gradient give a local
   Gaussian likelihood exp(-theta^T J_i theta / 2 + h_i^T theta). A device whose data do not see a parameter (a
   device without a rate table, for the parameters only the rate table fixes) has J_i = 0 there.
3. mu and s maximise the marginal likelihood prod_i integral N(theta | mu, Omega) exp(...) dtheta (closed-form EM
   iterations); then s maximises the restricted (REML) likelihood, which removes maximum likelihood's downward
   bias of a spread estimated from few devices, and mu is its generalised-least-squares estimate. Standard errors:
   mu's from its information sum_i (Omega + C_i)^-1, log s's from the restricted likelihood's observed
   information.
4. Every device is fitted again with the prior N(mu, Omega) (from where it stopped): its estimate is then the
   shrunken one (the posterior mode), its covariance the posterior's. Steps 2-4 repeat until mu and s move by
   less than `tol` of their standard errors (for a model linear in the random parameters one refit).

The standard errors of each device's estimates and scale factor add the uncertainty of mu and s (Kass and
Steffey's first-order correction): for the random parameters through the Gaussian posterior's derivative, for
the scale factor from refits with each of mu and log s moved by half its standard error. A device's scale factor
with sweeps missing (a device measured without a rate table) is then a prediction with a prediction interval.

The intervals are Student-t, not normal: the part of a scale factor's variance that the lot spread sets
(dSF/dmu_j^2 (s_j^2 + var mu_j), all of it for a prediction, ~none for a device whose own data fix it) is known
only as well as s_j, whose restricted likelihood gives var(log s_j); a variance estimated with nu degrees of
freedom has var(log s) = 1 / (2 nu), so nu_j = 1 / (2 var(log s_j)) (K - 1 for K devices that fix the parameter
precisely, which makes the prediction interval the textbook mu +/- t_{K-1} s sqrt(1 + 1/K)); the device's degrees
of freedom combine the parts by Welch-Satterthwaite. A normal interval with s from 4 devices covers ~86 %.

One concept per file: `solve.py` (`PopulationSolve`, the strategy), `results.py` (`PopulationFit`,
`PopulationParameter`), `distribution.py` (the lot distribution from the devices' local likelihoods, steps 2-3),
`intervals.py` (Student-t quantiles and degrees of freedom) and `population_fit.py` (the method).
"""

from .distribution import local_likelihoods as local_likelihoods, lot_distribution as lot_distribution
from .intervals import Z95 as Z95, interval_dof as interval_dof, t_quantile as t_quantile
from .population_fit import population_fit as population_fit
from .results import PopulationFit as PopulationFit, PopulationParameter as PopulationParameter
from .solve import PopulationSolve as PopulationSolve
