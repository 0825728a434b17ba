"""What the package reads and writes: file schemas and value checks, the resumable task cache,
package resources and flat-array layouts."""
