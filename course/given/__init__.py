"""The code each lab is given, not exercises: ``labN`` holds Lab N's checks and helpers."""
