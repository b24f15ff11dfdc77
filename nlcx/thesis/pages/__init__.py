"""The report pages of the thesis's outputs: a reproduction (``nlcx reproduce``: every table
beside the thesis, judged by configs/thesis/tolerances.yaml, the figures and the claims) and the
baselines (``nlcx baselines``). nlcx's report finds them by the kind of output directory its
manifest names, through the entry points ``reproduction`` and ``baselines`` of the group
``nlcx.pages`` (:mod:`nlcx.pages.kinds`)."""
