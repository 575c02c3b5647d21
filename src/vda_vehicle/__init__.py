"""vda_vehicle package."""
