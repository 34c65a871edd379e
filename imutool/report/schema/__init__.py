"""JSON schemas of the evidence reports (package so the schema files ship in wheels)."""
