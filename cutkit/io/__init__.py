"""File input and output: the model file, mesh import/export, atomic writes."""
