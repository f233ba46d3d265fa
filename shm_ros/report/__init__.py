"""Reports and plots (matplotlib, Agg backend)."""
