"""The bridge plant FMU: PumaPlant's interface in front of an external robot process (model.py,
the UDP protocol in protocol.py), and its slave script."""
