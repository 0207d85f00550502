"""Reading and writing logs (CSV, MCAP) and parameter files."""
