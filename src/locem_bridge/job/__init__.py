"""The job layer above PEMKRE/HICEM: runs a sequence of processes, shows progress, writes the run report."""
