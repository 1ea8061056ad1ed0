"""Campaigns: many simulated flights (Monte Carlo and falsification) on Dask (docs/campaign.md)."""
