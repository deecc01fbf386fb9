"""Headless batch tool: render Cycles passes with different seeds, compare runs, report bias."""
