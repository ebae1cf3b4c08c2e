"""The plant FMU: the arm of the paper touching the wall (model.py), and its slave script."""
