"""The case language's restricted expressions and their time jets."""
