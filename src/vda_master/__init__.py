"""vda_master package."""
