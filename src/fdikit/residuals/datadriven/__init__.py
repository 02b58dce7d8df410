"""Data-driven residual generators: PCA (T² and Q), dynamic PCA and canonical variate analysis.

Learnt from nominal records alone, with no model of the plant (Chiang, Russell & Braatz 2001;
Russell, Chiang & Braatz 2000): each is a :class:`~fdikit.base.stage.ResidualGenerator` whose
outputs are monitoring statistics with control limits at a confidence level, batch ``run`` and
streaming ``reset``/``step`` alike, saved as artifacts through ``to_dict``/``from_dict``.

* :mod:`.data` -- training records checked (NaN, constant channels, too few samples) and scaled;
* :mod:`.limits` -- T² limits (F distribution), Q limits (Jackson–Mudholkar), empirical ones;
* :mod:`.lags` -- lagged windows, the number of lags by AIC, the shared streaming window;
* :mod:`.pca` -- :class:`PCAResidual` (T², Q, per-channel contributions);
* :mod:`.dpca` -- :class:`DPCAResidual` (PCA on lagged windows);
* :mod:`.cva` -- :class:`CVAResidual` (T² of states and of residual variates, Q), its order by
  held-out prediction (:func:`heldout_order`).
"""

from .cva import CVAResidual, heldout_order
from .data import fit_scaling, training_data
from .dpca import DPCAResidual
from .lags import LaggedStatistic, lagged, select_lags
from .limits import empirical_limit, q_limit, t2_limit
from .pca import PCAResidual, n_components_parallel

__all__ = [
    "CVAResidual",
    "DPCAResidual",
    "LaggedStatistic",
    "PCAResidual",
    "empirical_limit",
    "fit_scaling",
    "heldout_order",
    "lagged",
    "n_components_parallel",
    "q_limit",
    "select_lags",
    "t2_limit",
    "training_data",
]
