"""Campaigns: many identification, nonlinearity or co-simulation runs on Dask workers.

A TOML spec (:mod:`duffid.campaign.spec`) gives the tasks; :func:`run_campaign`
(:mod:`duffid.campaign.runner`) runs them on a local cluster of processes or an existing
Dask cluster and streams the results to Parquet (:mod:`duffid.campaign.store`);
:mod:`duffid.campaign.summary` makes tables and plots of them. ``duffid campaign`` is the
command.
"""
from .runner import CampaignRun, run_campaign
from .spec import CampaignSpec, Task, load_spec
from .store import read_results

__all__ = ["load_spec", "run_campaign", "read_results", "CampaignSpec", "CampaignRun", "Task"]
