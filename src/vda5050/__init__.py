"""vda5050 package."""
