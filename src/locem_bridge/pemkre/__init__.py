"""PEMKRE: the semantic layer (ROS-free). Ontologies in a triplestore, process engine, execution log, KPIs."""
