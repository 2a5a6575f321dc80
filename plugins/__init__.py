"""Built-in processing steps, one package each; registered via the `pointspro.steps` entry points."""
