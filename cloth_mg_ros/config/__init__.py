"""Configuration: the one parameter schema (`schema`) and the body scenes' params files
(`scenes`: config/<scene>.yaml loaded and checked).
"""
