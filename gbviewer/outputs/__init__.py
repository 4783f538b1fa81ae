"""What is made of renders: images and figures, videos, flicker and difference measures, trace reports."""
