"""Reading scans from what users have, writing what they keep."""
