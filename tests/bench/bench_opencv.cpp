// cv::GaussianBlur on CV_32FC4 for bench_effects (C interface).
#include <opencv2/core.hpp>
#include <opencv2/imgproc.hpp>

extern "C" void bench_cv_set_threads(int n) { cv::setNumThreads(n); }

extern "C" void bench_cv_gaussian(const float *src, float *dst, int w, int h, int ksize)
{
    cv::Mat in(h, w, CV_32FC4, const_cast<float *>(src));
    cv::Mat out(h, w, CV_32FC4, dst);
    cv::GaussianBlur(in, out, cv::Size(ksize, ksize), 0, 0, cv::BORDER_REPLICATE);
}
