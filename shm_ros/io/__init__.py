"""Outside formats: rosbag2 bags, structure YAML, importers of other recording formats."""
