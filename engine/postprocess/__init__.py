"""Post-processing of rendered Stokes images (no re-rendering): virtual filters and false colour."""
